// Traces Pinocchio's own algorithms with casadi::SX as the scalar and saves each as a
// casadi::Function (<OUTDIR>/<name>.casadi): the "pinocchio_casadi_c" peer, i.e. what a user
// who wants the fastest Pinocchio-based code would write (Pinocchio + CasADi's C code
// generator).  benchmarks/pinocchio_casadi.py code-generates and times the saved Functions.
//
// usage: pinocchio_casadi_trace MODEL.txt OUTDIR
//   MODEL.txt: the DH arm as numbers (pinocchio_model.hpp, written by pinocchio_cpp.py).
//
// Every Function takes column vectors of n joint values and returns matrices (column-major,
// as CasADi stores them; CasADi's jacobians leave structural zeros out), under the names and
// port names of the generated functions (functions.json):
//   fk_hom(q) -> T            4x4 flange pose in the base frame (forwardKinematics +
//                             updateFramePlacement)
//   jacobian(q) -> J          6xn, rows v then w of the flange origin, base-frame axes
//                             (computeFrameJacobian, LOCAL_WORLD_ALIGNED)
//   M(q) -> M                 crba, mirrored to the full symmetric matrix
//   g(q) -> g                 computeGeneralizedGravity
//   c(q, qd) -> c             Coriolis/centrifugal only: rnea(q, qd, 0) on a gravity-free copy
//   tau(q, qd, qdd) -> tau    rnea
//   fd(q, qd, tau) -> qdd     aba
//   Minv(q) -> Minv           computeMinverse, mirrored to the full symmetric matrix
// and the derivatives in two candidate forms each, both saved so that the faster can be kept:
//   tau_derivatives(q, qd, qdd) -> (dtau_dq, dtau_dqd)           computeRNEADerivatives
//   tau_derivatives_ad(...)                                       casadi jacobian of traced rnea
//   fd_derivatives(q, qd, tau) -> (dqdd_dq, dqdd_dqd, Minv)       computeABADerivatives
//   fd_derivatives_ad(...)       casadi jacobian of traced aba; Minv by computeMinverse
// Units are those of the model file (SI, rad).
#include "sx_trace.hpp" // Pinocchio on casadi::SX: must precede the other Pinocchio headers

#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include "pinocchio_model.hpp"
#include "program_args.hpp"

#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

using namespace pinocchio;
static MatrixXs mirrored(MatrixXs m)
{
  mirror_upper(m);
  return m;
}

static void save(const std::string & dir, const std::string & name, const std::vector<Port> & inputs,
                 const std::vector<Port> & outputs)
{
  save_function(dir + "/" + name + ".casadi", name, inputs, outputs);
}

static const char USAGE[] =
  "usage: %s MODEL.txt OUTDIR\n"
  "Traces Pinocchio's algorithms for the arm in MODEL.txt (written by benchmarks/pinocchio_cpp.py)\n"
  "with casadi::SX and saves fk_hom, jacobian, M, g, c, tau, fd, tau_derivatives[_ad] and\n"
  "fd_derivatives[_ad] as OUTDIR/<name>.casadi (casadi.Function.load reads them).\n";

int main(int argc, char ** argv)
{
  if (const int code = check_args(argc, argv, 3, USAGE); code >= 0)
    return code;
  Model model;
  FrameIndex flange;
  if (!read_dh_model(argv[1], model, flange))
  {
    std::fprintf(stderr, "cannot read model file %s\n", argv[1]);
    return 1;
  }
  const std::string dir = argv[2];
  if (!std::filesystem::is_directory(dir)) // Function::save would fail silently
  {
    std::fprintf(stderr, "no such directory: %s\n", argv[2]);
    return 1;
  }
  const int n = model.nv;
  try
  {
    const ADModel ad = model.cast<SX>();
    ADModel gravity_free = ad;
    gravity_free.gravity.setZero();
    const Symbol q = symbol("q", n), qd = symbol("qd", n), qdd = symbol("qdd", n), tau = symbol("tau", n);
    const VectorXs zero = VectorXs::Zero(n);

    { // A fresh Data per Function: nothing of one trace leaks into the next.
      ADData data(ad);
      forwardKinematics(ad, data, q.eigen);
      const auto T = updateFramePlacement(ad, data, flange).toHomogeneousMatrix();
      save(dir, "fk_hom", {{"q", q.sx}}, {{"T", to_sx(T)}});
    }
    {
      ADData data(ad);
      ADData::Matrix6x J = ADData::Matrix6x::Zero(6, n);
      computeFrameJacobian(ad, data, q.eigen, flange, LOCAL_WORLD_ALIGNED, J);
      save(dir, "jacobian", {{"q", q.sx}}, {{"J", to_sx(J)}});
    }
    {
      ADData data(ad);
      save(dir, "M", {{"q", q.sx}}, {{"M", to_sx(mirrored(crba(ad, data, q.eigen)))}});
    }
    {
      ADData data(ad);
      save(dir, "g", {{"q", q.sx}}, {{"g", to_sx(computeGeneralizedGravity(ad, data, q.eigen))}});
    }
    {
      ADData data(gravity_free);
      save(dir, "c", {{"q", q.sx}, {"qd", qd.sx}},
           {{"c", to_sx(rnea(gravity_free, data, q.eigen, qd.eigen, zero))}});
    }
    SX rnea_sx, aba_sx; // kept for the AD candidates below
    {
      ADData data(ad);
      rnea_sx = to_sx(rnea(ad, data, q.eigen, qd.eigen, qdd.eigen));
      save(dir, "tau", {{"q", q.sx}, {"qd", qd.sx}, {"qdd", qdd.sx}}, {{"tau", rnea_sx}});
    }
    {
      ADData data(ad);
      aba_sx = to_sx(aba(ad, data, q.eigen, qd.eigen, tau.eigen));
      save(dir, "fd", {{"q", q.sx}, {"qd", qd.sx}, {"tau", tau.sx}}, {{"qdd", aba_sx}});
    }
    {
      ADData data(ad);
      save(dir, "Minv", {{"q", q.sx}}, {{"Minv", to_sx(mirrored(computeMinverse(ad, data, q.eigen)))}});
    }
    const std::vector<Port> rnea_in{{"q", q.sx}, {"qd", qd.sx}, {"qdd", qdd.sx}};
    const std::vector<Port> aba_in{{"q", q.sx}, {"qd", qd.sx}, {"tau", tau.sx}};
    {
      ADData data(ad);
      MatrixXs dq = MatrixXs::Zero(n, n), dv = MatrixXs::Zero(n, n), da = MatrixXs::Zero(n, n);
      computeRNEADerivatives(ad, data, q.eigen, qd.eigen, qdd.eigen, dq, dv, da);
      save(dir, "tau_derivatives", rnea_in, {{"dtau_dq", to_sx(dq)}, {"dtau_dqd", to_sx(dv)}});
    }
    save(dir, "tau_derivatives_ad", rnea_in,
         {{"dtau_dq", SX::jacobian(rnea_sx, q.sx)}, {"dtau_dqd", SX::jacobian(rnea_sx, qd.sx)}});
    {
      ADData data(ad);
      MatrixXs dq = MatrixXs::Zero(n, n), dv = MatrixXs::Zero(n, n), minv = MatrixXs::Zero(n, n);
      computeABADerivatives(ad, data, q.eigen, qd.eigen, tau.eigen, dq, dv, minv);
      // Minv comes out full: computeABADerivatives mirrors it itself to form -Minv dtau/dq.
      save(dir, "fd_derivatives", aba_in, {{"dqdd_dq", to_sx(dq)}, {"dqdd_dqd", to_sx(dv)}, {"Minv", to_sx(minv)}});
    }
    {
      ADData data(ad);
      const MatrixXs minv = mirrored(computeMinverse(ad, data, q.eigen));
      save(dir, "fd_derivatives_ad", aba_in,
           {{"dqdd_dq", SX::jacobian(aba_sx, q.sx)}, {"dqdd_dqd", SX::jacobian(aba_sx, qd.sx)},
            {"Minv", to_sx(minv)}});
    }
  }
  catch (const std::exception & e)
  {
    std::fprintf(stderr, "tracing failed: %s\n", e.what());
    return 1;
  }
  return 0;
}
