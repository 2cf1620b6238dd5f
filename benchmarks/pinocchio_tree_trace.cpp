// Traces one of Pinocchio's algorithms on a robot read from a URDF (a floating-base tree or an
// arm) with casadi::SX as the scalar and saves it as a casadi::Function (<OUTDIR>/<NAME>.casadi):
// the "pinocchio_casadi_c" column of benchmarks/trees.py (and of cppadcg_peer.py's URDF robots),
// which code-generates it with CasADi and times the C.  One function
// per run, so that Python can give each trace its own time limit (the graphs of a 35-dof
// humanoid are large).
//
// usage: pinocchio_tree_trace MODEL.bin FRAMES OUTDIR NAME
//   MODEL.bin: Model::saveToBinary of the model (see pinocchio_tree_bench.cpp
//              for why the model is serialized rather than parsed here).
//   FRAMES: comma-separated frame names (the k frames of fk_hom and jacobian).
//   NAME: one of
//     fk_hom(q) -> T            4k x 4: the k poses stacked (forwardKinematics +
//                               updateFramePlacement of the k frames)
//     jacobian(q) -> J          6k x nv: the k Jacobians stacked (computeJointJacobians +
//                               getFrameJacobian, LOCAL_WORLD_ALIGNED)
//     M(q) -> M                 crba, mirrored to the full symmetric matrix
//     g(q) -> g                 computeGeneralizedGravity
//     c(q, qd) -> c             nonLinearEffects on a gravity-free copy
//     tau(q, qd, qdd) -> tau    rnea
//     fd(q, qd, tau) -> qdd     aba
//     com(q) -> com, J_com, A_g jacobianCenterOfMass (com on the way) + computeCentroidalMap
//     Minv(q) -> Minv           computeMinverse, mirrored to the full symmetric matrix
//     tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd        computeRNEADerivatives
//     fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd, Minv   computeABADerivatives
//                               (derivatives in q by Pinocchio's tangent: nv columns)
// q has Pinocchio's nq entries (a continuous joint is cos, sin), the others nv.  Stacking the
// k frames' matrices vertically gives, read row-major, the generated (k, 4, 4) / (k, 6, nv).
#include "sx_trace.hpp" // Pinocchio on casadi::SX: must precede the other Pinocchio headers

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

#include "frame_list.hpp"
#include "program_args.hpp"

#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

using namespace pinocchio;
// The traced outputs of function `name` (empty: unknown name).
static std::vector<Port> trace(const std::string & name, const ADModel & ad, const std::vector<FrameIndex> & frames,
                               const Symbol & q, const Symbol & qd, const Symbol & qdd, const Symbol & tau)
{
  ADData data(ad);
  const int nv = ad.nv, k = (int)frames.size();
  if (name == "fk_hom")
  {
    forwardKinematics(ad, data, q.eigen);
    MatrixXs T(4 * k, 4);
    for (int i = 0; i < k; ++i)
      T.middleRows(4 * i, 4) = updateFramePlacement(ad, data, frames[i]).toHomogeneousMatrix();
    return {{"T", to_sx(T)}};
  }
  if (name == "jacobian")
  {
    computeJointJacobians(ad, data, q.eigen);
    MatrixXs J = MatrixXs::Zero(6 * k, nv);
    for (int i = 0; i < k; ++i)
    {
      ADData::Matrix6x Ji = ADData::Matrix6x::Zero(6, nv);
      getFrameJacobian(ad, data, frames[i], LOCAL_WORLD_ALIGNED, Ji);
      J.middleRows(6 * i, 6) = Ji;
    }
    return {{"J", to_sx(J)}};
  }
  if (name == "M")
  {
    MatrixXs M = crba(ad, data, q.eigen);
    M.triangularView<Eigen::StrictlyLower>() = M.transpose().triangularView<Eigen::StrictlyLower>();
    return {{"M", to_sx(M)}};
  }
  if (name == "g")
    return {{"g", to_sx(computeGeneralizedGravity(ad, data, q.eigen))}};
  if (name == "c")
  {
    ADModel gravity_free = ad;
    gravity_free.gravity.setZero();
    ADData free_data(gravity_free);
    return {{"c", to_sx(nonLinearEffects(gravity_free, free_data, q.eigen, qd.eigen))}};
  }
  if (name == "tau")
    return {{"tau", to_sx(rnea(ad, data, q.eigen, qd.eigen, qdd.eigen))}};
  if (name == "fd")
    return {{"qdd", to_sx(aba(ad, data, q.eigen, qd.eigen, tau.eigen))}};
  if (name == "com")
  {
    const MatrixXs Jcom = jacobianCenterOfMass(ad, data, q.eigen);
    const VectorXs com = data.com[0];
    const MatrixXs Ag = computeCentroidalMap(ad, data, q.eigen);
    return {{"com", to_sx(com)}, {"J_com", to_sx(Jcom)}, {"A_g", to_sx(Ag)}};
  }
  if (name == "Minv")
  {
    MatrixXs Minv = computeMinverse(ad, data, q.eigen);
    Minv.triangularView<Eigen::StrictlyLower>() = Minv.transpose().triangularView<Eigen::StrictlyLower>();
    return {{"Minv", to_sx(Minv)}};
  }
  if (name == "tau_derivatives" || name == "fd_derivatives")
  {
    MatrixXs dq = MatrixXs::Zero(nv, nv), dv = MatrixXs::Zero(nv, nv), dx = MatrixXs::Zero(nv, nv);
    if (name == "tau_derivatives")
    {
      computeRNEADerivatives(ad, data, q.eigen, qd.eigen, qdd.eigen, dq, dv, dx);
      return {{"dtau_dq", to_sx(dq)}, {"dtau_dqd", to_sx(dv)}};
    }
    // Minv comes out full: computeABADerivatives mirrors it itself to form -Minv dtau/dq.
    computeABADerivatives(ad, data, q.eigen, qd.eigen, tau.eigen, dq, dv, dx);
    return {{"dqdd_dq", to_sx(dq)}, {"dqdd_dqd", to_sx(dv)}, {"Minv", to_sx(dx)}};
  }
  return {};
}

static const char USAGE[] =
  "usage: %s MODEL.bin FRAMES OUTDIR NAME\n"
  "Traces Pinocchio's algorithm NAME (fk_hom, jacobian, M, g, c, tau, fd, com, Minv,\n"
  "tau_derivatives or fd_derivatives) on the serialized model MODEL.bin (written by\n"
  "benchmarks/trees.py) with casadi::SX and saves it as\n"
  "OUTDIR/NAME.casadi (casadi.Function.load reads it).\n";

int main(int argc, char ** argv)
{
  if (const int code = check_args(argc, argv, 5, USAGE); code >= 0)
    return code;
  const std::string dir = argv[3], name = argv[4];
  if (!std::filesystem::is_directory(dir)) // Function::save would fail silently
  {
    std::fprintf(stderr, "no such directory: %s\n", argv[3]);
    return 1;
  }
  try
  {
    Model model;
    model.loadFromBinary(argv[1]);
    const std::vector<FrameIndex> frames = frame_ids(model, argv[2]);
    const ADModel ad = model.cast<SX>();
    const Symbol q = symbol("q", model.nq), qd = symbol("qd", model.nv), qdd = symbol("qdd", model.nv),
                 tau = symbol("tau", model.nv);
    const std::vector<Port> outputs = trace(name, ad, frames, q, qd, qdd, tau);
    if (outputs.empty())
    {
      std::fprintf(stderr, "unknown function %s\n", name.c_str());
      return 2;
    }
    std::vector<Port> inputs{{"q", q.sx}};
    const bool inverse = name == "tau" || name == "tau_derivatives", forward = name == "fd" || name == "fd_derivatives";
    if (name == "c" || inverse || forward)
      inputs.push_back({"qd", qd.sx});
    if (inverse)
      inputs.push_back({"qdd", qdd.sx});
    if (forward)
      inputs.push_back({"tau", tau.sx});
    save_function(dir + "/" + name + ".casadi", name, inputs, outputs);
  }
  catch (const std::exception & e)
  {
    std::fprintf(stderr, "tracing %s failed: %s\n", name.c_str(), e.what());
    return 1;
  }
  return 0;
}
