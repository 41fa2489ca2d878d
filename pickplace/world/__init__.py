"""The world the robot works in: bins, the object, the floor; the
:class:`~pickplace.world.scene.Scene`
that holds the composed model and its :class:`~pickplace.robot.compose.Robot`, and where objects
are placed.
"""
