"""Differential IK each control tick: the controllers (QP, pinv, DLS), the arm's kinematics and the
kinematic-health diagnostics (σ, condition, manipulability).
"""
