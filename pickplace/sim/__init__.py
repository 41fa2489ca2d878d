"""One task simulated: the loop, its tick log, the checks that judge it, goals and verdict, faults,
named scenarios, varied parameters and the scene loader.
"""
