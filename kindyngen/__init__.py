"""KinDynGen: symbolic kinematics and dynamics of serial arms and kinematic trees, generated as C, Python and CasADi.

The package is the pipeline, one module per stage:

robot (YAML -> RobotModel) -> geometry (exact DH transforms) -> kinematics_homogeneous /
kinematics_dualquat / dynamics_* (SymbolicFunction DAGs) -> optimize (CSE) and opcount ->
printer + render (C / Python / CasADi through kindyngen/codegen/templates/) -> pipeline (writes generated/).
"""
__version__ = "0.1.0"
