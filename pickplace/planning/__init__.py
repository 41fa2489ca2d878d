"""From the object's pose to a timed plan: grasps, keyframes, the trajectory, its timing by the
robot's
limits and the pre-flight against the robot, chosen among candidates by the planner.
"""
