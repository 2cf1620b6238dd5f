// The DH arm "as numbers" for Pinocchio, shared by pinocchio_bench.cpp (timing in double) and
// pinocchio_casadi_trace.cpp (tracing with casadi::SX), so that both read exactly the same
// robot.  benchmarks/pinocchio_cpp.py (model_text) writes the file:
//   n; gx gy gz; per joint: R(9, row-major) p(3) mass com(3) Ixx Ixy Ixz Iyy Iyz Izz
//   (joint placement in the parent joint frame, inertia in the joint frame, about the CoM);
//   then the flange placement R(9) p(3) in the last joint frame.
// Every joint is revolute about its z axis.
#pragma once

#include <pinocchio/multibody.hpp>

#include <fstream>
#include <string>

// Reads the model file into `model` (gravity, joints, inertias, an OP_FRAME "flange") and
// stores the flange frame's index; false when the file is missing or cut short.
inline bool read_dh_model(const char * path, pinocchio::Model & model, pinocchio::FrameIndex & flange)
{
  using namespace pinocchio;
  std::ifstream mf(path);
  int n = 0;
  double gx, gy, gz;
  mf >> n >> gx >> gy >> gz;
  if (!mf || n <= 0)
    return false;
  model = Model();
  model.gravity.linear() = Eigen::Vector3d(gx, gy, gz);
  JointIndex parent = 0;
  for (int i = 0; i < n; ++i)
  {
    Eigen::Matrix3d R, I;
    Eigen::Vector3d p, c;
    double m;
    for (int k = 0; k < 9; ++k)
      mf >> R(k / 3, k % 3);
    mf >> p[0] >> p[1] >> p[2] >> m >> c[0] >> c[1] >> c[2];
    mf >> I(0, 0) >> I(0, 1) >> I(0, 2) >> I(1, 1) >> I(1, 2) >> I(2, 2);
    I(1, 0) = I(0, 1);
    I(2, 0) = I(0, 2);
    I(2, 1) = I(1, 2);
    parent = model.addJoint(parent, JointModelRZ(), SE3(R, p), "joint" + std::to_string(i + 1));
    model.appendBodyToJoint(parent, Inertia(m, c, Symmetric3(I)), SE3::Identity());
  }
  Eigen::Matrix3d Rf;
  Eigen::Vector3d pf;
  for (int k = 0; k < 9; ++k)
    mf >> Rf(k / 3, k % 3);
  mf >> pf[0] >> pf[1] >> pf[2];
  if (!mf)
    return false;
  flange = model.addFrame(Frame("flange", parent, 0, SE3(Rf, pf), FrameType::OP_FRAME));
  return true;
}

// Pinocchio's crba and computeMinverse fill the upper triangle only; the generated functions
// return the full symmetric matrix.
template<typename MatrixType>
inline void mirror_upper(MatrixType & m)
{
  for (Eigen::Index r = 1; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < r; ++c)
      m(r, c) = m(c, r);
}
