"""The robot: its description (robot.toml), the MJCF parts it names, their physics, the gripper's
calibration and the composition into a world (:func:`pickplace.robot.compose.load_robot`).
"""
