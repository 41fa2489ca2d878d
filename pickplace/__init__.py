"""pickplace: a 7-DoF arm picks a red brick from one bin and places it in another."""
