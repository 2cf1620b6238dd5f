"""Inverse kinematics: the closed form of LWR-type arms, and damped least squares for any arm."""
