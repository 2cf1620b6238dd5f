"""The kinematics paper's Table II and Fig. 1 (Maple 2018 counts, MATLAB 2017b times on an
i7-6700K at 4 GHz), as restated in shared/reference.md, for side-by-side tables."""

# computation -> (generated function, {"optimized"/"unoptimized": (add, mul, call)})
TABLE_II = {
    "FK homogeneous": ("fk_hom", {"unoptimized": (88, 238, 327), "optimized": (40, 87, 14)}),
    "FK dual quaternion": ("fk_dq", {"unoptimized": (312, 1576, 880), "optimized": (38, 88, 14)}),
    "IK homogeneous": ("ik_hom", {"optimized": (1461, 2570, 52)}),
    "IK dual quaternion": ("ik_dq", {"optimized": (1070, 2258, 184)}),
}

# Mean time per computation in MATLAB, microseconds (optimized code; Fig. 1).
MATLAB_US = {"fk_hom": 3.642, "fk_dq": 4.398, "ik_hom": 86.138, "ik_dq": 173.104}
MATLAB_UNOPTIMIZED_US = {"fk_hom": 4.109, "fk_dq": 19.510}
