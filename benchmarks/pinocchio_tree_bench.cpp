// Times Pinocchio's C++ algorithms on a robot read from a URDF, a kinematic tree with a
// floating base or an arm (the "pinocchio_cpp" column of benchmarks/trees.py and of
// benchmarks/cppadcg_peer.py's URDF robots), the same way the C harness times the
// generated code: cycle over K precomputed inputs, CLOCK_MONOTONIC, results summed into a
// volatile sink.
//
// The model is Pinocchio's own buildModelFromUrdf(path[, JointModelFreeFlyer()]), run by
// benchmarks/trees.py through Pinocchio's Python bindings and handed over with Pinocchio's
// serialization (Model::saveToBinary / loadFromBinary): parsing the URDF here would mean
// linking the wheel's precompiled libpinocchio_parsers, whose Eigen objects are laid out for
// 16-byte alignment and crash next to this -march=native (AVX, 32-byte) build; the
// serialized model is plain numbers and needs only libboost_serialization.
//
// usage: pinocchio_tree_bench MODEL.bin FRAMES INPUTS.bin K REPEATS TARGET_NS
//   MODEL.bin: Model::saveToBinary of the model.
//   FRAMES: comma-separated frame names (the k frames of fk_hom and jacobian).
//   INPUTS.bin: doubles q[K][nq], qd[K][nv], qdd[K][nv], tau[K][nv] in Pinocchio's layout.
// output: "time NAME t1 ... tR" (ns per call in each repetition) per function, then
// "check NAME PORT values..." for input 0, row-major, in the generated functions' layout
// (fk_hom: k 4x4 poses; jacobian: k 6 x nv; M and Minv full; com: com, J_com, A_g;
// tau_derivatives: dtau_dq, dtau_dqd; fd_derivatives: dqdd_dq, dqdd_dqd, Minv; the derivatives
// in q by Pinocchio's tangent (nv columns), as the generated ones).
#include <pinocchio/multibody.hpp>
#include <pinocchio/serialization.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>

#include "bench_timing.hpp"
#include "program_args.hpp"
#include "frame_list.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace pinocchio;

static void print(const char * name, int port, const Eigen::MatrixXd & m)
{
  std::printf("check %s %d", name, port);
  for (Eigen::Index r = 0; r < m.rows(); ++r) // row-major, as the generated code
    for (Eigen::Index c = 0; c < m.cols(); ++c)
      std::printf(" %.17g", m(r, c));
  std::printf("\n");
}

static const char USAGE[] =
  "usage: %s MODEL.bin FRAMES INPUTS.bin K REPEATS TARGET_NS\n"
  "Times Pinocchio's algorithms (fk_hom, jacobian, M, g, c, tau, fd, com, Minv, tau_derivatives,\n"
  "fd_derivatives) on the serialized model MODEL.bin (floating or fixed base) for the\n"
  "comma-separated FRAMES over the K inputs in INPUTS.bin\n"
  "(both written by benchmarks/trees.py): REPEATS repetitions of about TARGET_NS each; prints\n"
  "\"time NAME ns...\" lines, then \"check NAME PORT values...\" lines for input 0.\n";

int main(int argc, char ** argv)
{
  if (const int code = check_args(argc, argv, 7, USAGE); code >= 0)
    return code;
  const long K = std::atol(argv[4]);
  const int repeats = std::atoi(argv[5]);
  const double target_ns = std::atof(argv[6]);

  Model model;
  std::vector<FrameIndex> frames;
  try
  {
    model.loadFromBinary(argv[1]);
    frames = frame_ids(model, argv[2]);
  }
  catch (const std::exception & e)
  {
    std::fprintf(stderr, "cannot load %s: %s\n", argv[1], e.what());
    return 1;
  }
  // c alone (no gravity): nonLinearEffects on a gravity-free copy, one call as for the others.
  Model gravity_free = model;
  gravity_free.gravity.setZero();
  const int nq = model.nq, nv = model.nv;
  Data data(model), data_free(gravity_free);

  const size_t per_input = nq + 3 * nv;
  std::vector<double> raw(K * per_input);
  std::FILE * f = std::fopen(argv[3], "rb");
  if (!f || std::fread(raw.data(), sizeof(double), raw.size(), f) != raw.size())
  {
    std::fprintf(stderr, "cannot read %ld inputs from %s\n", K, argv[3]);
    return 1;
  }
  std::fclose(f);
  // Inputs as Eigen vectors built once: the timed loops only call the algorithms.
  std::vector<Eigen::VectorXd> q(K), qd(K), qdd(K), tau(K);
  const double * at = raw.data();
  for (long k = 0; k < K; ++k, at += nq)
    q[k] = Eigen::Map<const Eigen::VectorXd>(at, nq);
  for (auto * vectors : {&qd, &qdd, &tau})
    for (long k = 0; k < K; ++k, at += nv)
      (*vectors)[k] = Eigen::Map<const Eigen::VectorXd>(at, nv);

  // getFrameJacobian writes the columns of the joints supporting the frame only; the others
  // are zeroed once and stay zero, as in a user's loop.
  std::vector<Data::Matrix6x> J(frames.size(), Data::Matrix6x::Zero(6, nv));

  // forwardKinematics + updateFramePlacement of the k frames: cheaper than
  // framesForwardKinematics, which places every frame of the model.
  measure("fk_hom", K, repeats, target_ns, [&](long k) {
    forwardKinematics(model, data, q[k]);
    double acc = 0;
    for (FrameIndex id : frames)
      acc += updateFramePlacement(model, data, id).translation()[0];
    return acc;
  });
  measure("jacobian", K, repeats, target_ns, [&](long k) {
    computeJointJacobians(model, data, q[k]);
    for (size_t i = 0; i < frames.size(); ++i)
      getFrameJacobian(model, data, frames[i], LOCAL_WORLD_ALIGNED, J[i]);
    return J[0](0, 0);
  });
  // crba fills the upper triangle only (the generated M is full): a small head start.
  measure("M", K, repeats, target_ns, [&](long k) { return crba(model, data, q[k])(0, 0); });
  measure("g", K, repeats, target_ns, [&](long k) {
    return computeGeneralizedGravity(model, data, q[k])[0];
  });
  measure("c", K, repeats, target_ns, [&](long k) {
    return nonLinearEffects(gravity_free, data_free, q[k], qd[k])[0];
  });
  measure("tau", K, repeats, target_ns, [&](long k) {
    return rnea(model, data, q[k], qd[k], qdd[k])[0];
  });
  measure("fd", K, repeats, target_ns, [&](long k) {
    return aba(model, data, q[k], qd[k], tau[k])[0];
  });
  // jacobianCenterOfMass computes the centre of mass on the way (data.com[0]), so it and
  // computeCentroidalMap give all three outputs; a separate centerOfMass would be redundant.
  measure("com", K, repeats, target_ns, [&](long k) {
    const double jc = jacobianCenterOfMass(model, data, q[k])(0, 0);
    return jc + data.com[0][0] + computeCentroidalMap(model, data, q[k])(0, 0);
  });

  // computeMinverse fills the upper triangle only, as crba.
  measure("Minv", K, repeats, target_ns, [&](long k) { return computeMinverse(model, data, q[k])(0, 0); });
  // Derivative outputs zeroed once, as computeRNEADerivatives asks: every call assigns the same
  // entries, so the timed calls need no reset (as in pinocchio_bench.cpp).
  Eigen::MatrixXd d_dq = Eigen::MatrixXd::Zero(nv, nv), d_dv = Eigen::MatrixXd::Zero(nv, nv),
                  d_dx = Eigen::MatrixXd::Zero(nv, nv);
  measure("tau_derivatives", K, repeats, target_ns, [&](long k) {
    computeRNEADerivatives(model, data, q[k], qd[k], qdd[k], d_dq, d_dv, d_dx);
    return d_dq(0, 1);
  });
  measure("fd_derivatives", K, repeats, target_ns, [&](long k) {
    computeABADerivatives(model, data, q[k], qd[k], tau[k], d_dq, d_dv, d_dx);
    return d_dq(0, 1);
  });

  // Results for input 0, compared with the generated code by Python.
  forwardKinematics(model, data, q[0]);
  std::printf("check fk_hom 0");
  for (FrameIndex id : frames)
  {
    const Eigen::Matrix4d T = updateFramePlacement(model, data, id).toHomogeneousMatrix();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        std::printf(" %.17g", T(r, c));
  }
  std::printf("\n");
  computeJointJacobians(model, data, q[0]);
  Eigen::MatrixXd stacked(6 * frames.size(), nv);
  for (size_t i = 0; i < frames.size(); ++i)
  {
    J[i].setZero();
    getFrameJacobian(model, data, frames[i], LOCAL_WORLD_ALIGNED, J[i]);
    stacked.middleRows(6 * i, 6) = J[i];
  }
  print("jacobian", 0, stacked);
  Eigen::MatrixXd M = crba(model, data, q[0]);
  M.triangularView<Eigen::StrictlyLower>() = M.transpose().triangularView<Eigen::StrictlyLower>();
  print("M", 0, M);
  print("g", 0, computeGeneralizedGravity(model, data, q[0]));
  print("c", 0, nonLinearEffects(gravity_free, data_free, q[0], qd[0]));
  print("tau", 0, rnea(model, data, q[0], qd[0], qdd[0]));
  print("fd", 0, aba(model, data, q[0], qd[0], tau[0]));
  Eigen::MatrixXd Minv = computeMinverse(model, data, q[0]);
  Minv.triangularView<Eigen::StrictlyLower>() = Minv.transpose().triangularView<Eigen::StrictlyLower>();
  print("Minv", 0, Minv);
  d_dq.setZero();
  d_dv.setZero();
  d_dx.setZero();
  computeRNEADerivatives(model, data, q[0], qd[0], qdd[0], d_dq, d_dv, d_dx);
  print("tau_derivatives", 0, d_dq);
  print("tau_derivatives", 1, d_dv);
  d_dq.setZero();
  d_dv.setZero();
  d_dx.setZero();
  computeABADerivatives(model, data, q[0], qd[0], tau[0], d_dq, d_dv, d_dx); // Minv full
  print("fd_derivatives", 0, d_dq);
  print("fd_derivatives", 1, d_dv);
  print("fd_derivatives", 2, d_dx);
  const Eigen::MatrixXd Jcom = jacobianCenterOfMass(model, data, q[0]);
  print("com", 0, data.com[0]);
  print("com", 1, Jcom);
  print("com", 2, computeCentroidalMap(model, data, q[0]));
  return sink == 12345.678 ? 3 : 0; // read the sink so it cannot be optimised out
}
