"""The dual-quaternion route: forward kinematics and dynamics written with unit dual quaternions."""
