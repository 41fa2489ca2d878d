"""pickplace: an arm with a gripper, described in a robot file, picks a red brick from one bin
and places it in another."""
