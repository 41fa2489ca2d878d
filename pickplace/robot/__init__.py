"""The robot: its description (robot.toml), the MJCF parts it names, their physics, the gripper's
calibration and the composition into a world (:func:`pickplace.robot.compose.load_robot`).
"""

# The robot a run uses unless told otherwise (a bundled robot's name, see
# pickplace.robot.registry); here so that the command line can name it without importing more.
DEFAULT_ROBOT = "iiwa14-wsg50"
