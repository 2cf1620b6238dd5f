// Times Pinocchio's C++ algorithms on a DH arm read from a data file, in the same way the
// C harness times the generated code (cycle over precomputed inputs, CLOCK_MONOTONIC,
// outputs summed into a volatile sink).  The model is read at run time, not compiled in,
// so that one (slow: minutes) header-only build serves every robot; benchmarks/pinocchio_cpp.py
// writes the model file and the inputs and parses the output.
//
// usage: pinocchio_bench MODEL.txt INPUTS.bin K REPEATS TARGET_NS
//   MODEL.txt: the DH arm as numbers (format in pinocchio_model.hpp).
//   INPUTS.bin: doubles q[K][n], qd[K][n], qdd[K][n], tau[K][n].
// output: one line per algorithm "time name t1 ... tR" (ns per call in each repetition), then
// "check name values..." lines with the results for input 0 ("check name.output values..."
// for each output of a function with several, in order), so that Python can confirm this is
// the same robot.
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/regressor.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>

#include "bench_timing.hpp"
#include "program_args.hpp"
#include "pinocchio_model.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace pinocchio;

static const char USAGE[] =
  "usage: %s MODEL.txt INPUTS.bin K REPEATS TARGET_NS\n"
  "Times Pinocchio's algorithms on the arm in MODEL.txt over the K inputs in INPUTS.bin (both\n"
  "written by benchmarks/pinocchio_cpp.py): REPEATS repetitions of about TARGET_NS each; prints\n"
  "\"time NAME ns...\" lines, then \"check NAME values...\" lines for input 0.\n";

int main(int argc, char ** argv)
{
  if (const int code = check_args(argc, argv, 6, USAGE); code >= 0)
    return code;
  const long K = std::atol(argv[3]);
  const int repeats = std::atoi(argv[4]);
  const double target_ns = std::atof(argv[5]);

  Model model;
  FrameIndex flange;
  if (!read_dh_model(argv[1], model, flange))
  {
    std::fprintf(stderr, "cannot read model file %s\n", argv[1]);
    return 1;
  }
  const int n = model.nv;
  Data data(model);

  std::vector<double> raw(4 * K * n);
  std::FILE * f = std::fopen(argv[2], "rb");
  if (!f || std::fread(raw.data(), sizeof(double), raw.size(), f) != raw.size())
  {
    std::fprintf(stderr, "cannot read %ld inputs from %s\n", K, argv[2]);
    return 1;
  }
  std::fclose(f);
  // Inputs as Eigen vectors built once: the timed loops only call the algorithm.
  std::vector<Eigen::VectorXd> q(K), qd(K), qdd(K), tau(K);
  for (long k = 0; k < K; ++k)
  {
    q[k] = Eigen::Map<Eigen::VectorXd>(&raw[(0 * K + k) * n], n);
    qd[k] = Eigen::Map<Eigen::VectorXd>(&raw[(1 * K + k) * n], n);
    qdd[k] = Eigen::Map<Eigen::VectorXd>(&raw[(2 * K + k) * n], n);
    tau[k] = Eigen::Map<Eigen::VectorXd>(&raw[(3 * K + k) * n], n);
  }
  Data::Matrix6x J(6, n);
  J.setZero();
  // Derivative outputs, zeroed once as computeRNEADerivatives asks: every call assigns the
  // same entries (the others stay zero), so the timed calls need no reset, as in a user's loop.
  Eigen::MatrixXd d_dq = Eigen::MatrixXd::Zero(n, n), d_dv = Eigen::MatrixXd::Zero(n, n),
                  d_da = Eigen::MatrixXd::Zero(n, n);

  measure("fk", K, repeats, target_ns, [&](long k) {
    forwardKinematics(model, data, q[k]);
    return updateFramePlacement(model, data, flange).translation()[0];
  });
  // LOCAL_WORLD_ALIGNED: flange-point linear velocity and angular velocity, both in the
  // base frame, as the generated geometric Jacobian.  computeFrameJacobian runs the
  // kinematics it needs itself, as the generated function does.
  measure("jacobian", K, repeats, target_ns, [&](long k) {
    computeFrameJacobian(model, data, q[k], flange, LOCAL_WORLD_ALIGNED, J);
    return J(0, 0);
  });
  measure("tau", K, repeats, target_ns, [&](long k) {
    return rnea(model, data, q[k], qd[k], qdd[k])[0];
  });
  // crba fills the upper triangle only (the generated M is full): a small head start.
  measure("M", K, repeats, target_ns, [&](long k) { return crba(model, data, q[k])(0, 0); });
  measure("g", K, repeats, target_ns, [&](long k) {
    return computeGeneralizedGravity(model, data, q[k])[0];
  });
  // nonLinearEffects = c + g: Pinocchio has no Coriolis-only vector, so this costs it
  // slightly more than the generated c.
  measure("c", K, repeats, target_ns, [&](long k) {
    return nonLinearEffects(model, data, q[k], qd[k])[0];
  });
  measure("S", K, repeats, target_ns, [&](long k) {
    return computeCoriolisMatrix(model, data, q[k], qd[k])(0, 0);
  });
  measure("fd", K, repeats, target_ns, [&](long k) {
    return aba(model, data, q[k], qd[k], tau[k])[0];
  });
  // computeMinverse fills the upper triangle only, as crba.
  measure("Minv", K, repeats, target_ns, [&](long k) { return computeMinverse(model, data, q[k])(0, 0); });
  measure("tau_derivatives", K, repeats, target_ns, [&](long k) {
    computeRNEADerivatives(model, data, q[k], qd[k], qdd[k], d_dq, d_dv, d_da);
    return d_dq(0, 1);
  });
  measure("fd_derivatives", K, repeats, target_ns, [&](long k) {
    computeABADerivatives(model, data, q[k], qd[k], tau[k], d_dq, d_dv, d_da);
    return d_dq(0, 1);
  });
  // Full 10n-column regressor (the generated Y has the base-parameter columns only).
  measure("Y", K, repeats, target_ns, [&](long k) {
    return computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k])(0, 0);
  });

  // Results for input 0, compared with the generated code by Python.
  forwardKinematics(model, data, q[0]);
  const SE3 & T = updateFramePlacement(model, data, flange);
  std::printf("check fk");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      std::printf(" %.17g", c < 3 ? T.rotation()(r, c) : T.translation()[r]);
  std::printf("\n");
  auto print = [](const char * name, const Eigen::MatrixXd & m) {
    std::printf("check %s", name);
    for (Eigen::Index r = 0; r < m.rows(); ++r) // row-major, as the generated code
      for (Eigen::Index c = 0; c < m.cols(); ++c)
        std::printf(" %.17g", m(r, c));
    std::printf("\n");
  };
  print("tau", rnea(model, data, q[0], qd[0], qdd[0]));
  J.setZero();
  computeFrameJacobian(model, data, q[0], flange, LOCAL_WORLD_ALIGNED, J);
  print("jacobian", J);
  Eigen::MatrixXd M = crba(model, data, q[0]);
  M.triangularView<Eigen::StrictlyLower>() = M.transpose().triangularView<Eigen::StrictlyLower>();
  print("M", M);
  const Eigen::VectorXd g = computeGeneralizedGravity(model, data, q[0]);
  print("g", g);
  print("c", nonLinearEffects(model, data, q[0], qd[0]) - g); // Coriolis/centrifugal alone
  print("fd", aba(model, data, q[0], qd[0], tau[0]));
  Eigen::MatrixXd Minv = computeMinverse(model, data, q[0]);
  mirror_upper(Minv);
  print("Minv", Minv);
  // Derivative checks in the generated layout: one line per output, row-major.
  d_dq.setZero();
  d_dv.setZero();
  d_da.setZero();
  computeRNEADerivatives(model, data, q[0], qd[0], qdd[0], d_dq, d_dv, d_da);
  print("tau_derivatives.dtau_dq", d_dq);
  print("tau_derivatives.dtau_dqd", d_dv);
  d_dq.setZero();
  d_dv.setZero();
  d_da.setZero();
  computeABADerivatives(model, data, q[0], qd[0], tau[0], d_dq, d_dv, d_da); // Minv full
  print("fd_derivatives.dqdd_dq", d_dq);
  print("fd_derivatives.dqdd_dqd", d_dv);
  print("fd_derivatives.Minv", d_da);
  return sink == 12345.678 ? 3 : 0; // read the sink so it cannot be optimised out
}
