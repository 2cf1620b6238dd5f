// Pinocchio's own CppADCodeGen code generation (pinocchio/codegen/cppadcg-algo.hpp: CodeGenRNEA,
// CodeGenABA, CodeGenCRBA, CodeGenMinv, CodeGenRNEADerivatives, CodeGenABADerivatives), the
// "pinocchio_cppadcg" peer of benchmarks/cppadcg_peer.py.  Pinocchio's CodeGenBase tapes the
// algorithm with CppAD<CG<double>> as the scalar, optimises the tape and has CppADCodeGen write
// C; its compileLib() would then compile a shared library with its own gcc call and dlopen it.
// Here the C sources are written to a folder instead (CppADCodeGen's
// SaveFilesModelLibraryProcessor), so that Python compiles them with the flags of the
// comparison and calls <name>_forward_zero from the same C harness that times the generated
// code.  A second mode evaluates Pinocchio's own algorithms in double, the values the
// generated library must reproduce before it is timed.
//
// usage: pinocchio_cppadcg_gen generate MODEL OUTDIR NAME...
//        pinocchio_cppadcg_gen reference MODEL INPUTS.bin NAME...
//   MODEL: a DH arm as numbers (.txt, pinocchio_model.hpp) or Model::saveToBinary of a URDF's
//          model (.bin, written by Pinocchio's Python bindings: see pinocchio_tree_bench.cpp).
//   NAME: one of
//     tau              rnea(q, v, a)                       in  x = (q, v, a)     out tau
//     fd               aba(q, v, tau)                      in  x = (q, v, tau)   out ddq
//     M                crba(q), upper triangle row by row  in  x = q             out n(n+1)/2
//     Minv             computeMinverse(q), the same        in  x = q             out n(n+1)/2
//     tau_derivatives  computeRNEADerivatives              in  x = (q, v, a)     out dtau_dq, dtau_dv, dtau_da
//     fd_derivatives   computeABADerivatives               in  x = (q, v, tau)   out ddq_dq, ddq_dv, ddq_dtau
//   (the matrices of the derivatives row-major, one after the other; Pinocchio's layout).
//   generate: OUTDIR/<NAME>/ gets the C sources of function NAME (forward zero order only:
//     <NAME>_forward_zero(double const *const *in, double *const *out, struct LangCAtomicFun)),
//     and one line "generated NAME TAPE_S SOURCE_S TAPE_CPU_S SOURCE_CPU_S" per function: the
//     seconds (wall, then CPU) of taping + optimising and of writing the C.
//   reference: INPUTS.bin holds q[nq], v[nv], a[nv], tau[nv] (one state); prints
//     "check NAME PORT values..." with Pinocchio's double results in the generated functions'
//     layout (full matrices row-major: M and Minv mirrored; tau_derivatives dtau_dq, dtau_dqd;
//     fd_derivatives dqdd_dq, dqdd_dqd, Minv).
#include <pinocchio/codegen/cppadcg.hpp> // CppAD's scalar traits: before any other Pinocchio header
#include <pinocchio/codegen/cppadcg-algo.hpp>
#include <pinocchio/serialization.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>

#include "pinocchio_model.hpp"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

using namespace pinocchio;

static const char USAGE[] =
  "usage: %s generate MODEL OUTDIR NAME...\n"
  "       %s reference MODEL INPUTS.bin NAME...\n"
  "Pinocchio's CppADCodeGen generators (tau fd M Minv tau_derivatives fd_derivatives) on the\n"
  "robot in MODEL (.txt: a DH arm as numbers; .bin: Model::saveToBinary): 'generate' writes\n"
  "each function's C sources to OUTDIR/NAME/ and prints \"generated NAME tape_s source_s\n"
  "tape_cpu_s source_cpu_s\"; 'reference' prints Pinocchio's double results for the state in\n"
  "INPUTS.bin (q, v, a, tau) as \"check NAME PORT values...\" lines.\n";

// The wrapper classes in Pinocchio's codegen module; its function name is also the prefix of
// the generated C function.
static std::unique_ptr<CodeGenBase<double>> generator(const std::string & name, const Model & model)
{
  if (name == "tau")
    return std::make_unique<CodeGenRNEA<double>>(model, name);
  if (name == "fd")
    return std::make_unique<CodeGenABA<double>>(model, name);
  if (name == "M")
    return std::make_unique<CodeGenCRBA<double>>(model, name);
  if (name == "Minv")
    return std::make_unique<CodeGenMinv<double>>(model, name);
  if (name == "tau_derivatives")
    return std::make_unique<CodeGenRNEADerivatives<double>>(model, name);
  if (name == "fd_derivatives")
    return std::make_unique<CodeGenABADerivatives<double>>(model, name);
  return nullptr;
}

struct Clocks
{
  std::chrono::steady_clock::time_point wall = std::chrono::steady_clock::now();
  std::clock_t cpu = std::clock();
  double wall_s() const
  {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall).count();
  }
  double cpu_s() const { return double(std::clock() - cpu) / CLOCKS_PER_SEC; }
};

static int generate(const Model & model, const std::string & outdir, const std::vector<std::string> & names)
{
  for (const std::string & name : names)
  {
    std::unique_ptr<CodeGenBase<double>> gen = generator(name, model);
    if (!gen)
    {
      std::fprintf(stderr, "unknown function %s\n", name.c_str());
      return 2;
    }
    Clocks tape;
    gen->initLib(); // tape the algorithm and optimise the tape
    // Only the zero-order forward sweep is timed: CodeGenRNEA and CodeGenABA would also emit a
    // dense Jacobian (CppAD's AD of the tape), which doubles their generation and compile time.
    gen->codeGenerator().setCreateJacobian(false);
    const double tape_s = tape.wall_s(), tape_cpu = tape.cpu_s();
    Clocks source;
    CppAD::cg::ModelLibraryCSourceGen<double> library(gen->codeGenerator());
    const std::filesystem::path folder = std::filesystem::path(outdir) / name;
    std::filesystem::create_directories(folder); // CppADCodeGen creates the last folder only
    CppAD::cg::SaveFilesModelLibraryProcessor<double>::saveLibrarySourcesTo(library, folder.string());
    std::printf("generated %s %.4f %.4f %.4f %.4f\n", name.c_str(), tape_s, source.wall_s(), tape_cpu,
                source.cpu_s());
    std::fflush(stdout);
  }
  return 0;
}

static void print(const char * name, int port, const Eigen::MatrixXd & m)
{
  std::printf("check %s %d", name, port);
  for (Eigen::Index r = 0; r < m.rows(); ++r) // row-major, as the generated code
    for (Eigen::Index c = 0; c < m.cols(); ++c)
      std::printf(" %.17g", m(r, c));
  std::printf("\n");
}

static int reference(const Model & model, const char * inputs, const std::vector<std::string> & names)
{
  const int nq = model.nq, nv = model.nv;
  std::vector<double> raw(nq + 3 * nv);
  std::FILE * f = std::fopen(inputs, "rb");
  if (!f || std::fread(raw.data(), sizeof(double), raw.size(), f) != raw.size())
  {
    std::fprintf(stderr, "cannot read one state (q, v, a, tau) from %s\n", inputs);
    return 1;
  }
  std::fclose(f);
  const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(raw.data(), nq),
                        v = Eigen::Map<const Eigen::VectorXd>(raw.data() + nq, nv),
                        a = Eigen::Map<const Eigen::VectorXd>(raw.data() + nq + nv, nv),
                        tau = Eigen::Map<const Eigen::VectorXd>(raw.data() + nq + 2 * nv, nv);
  Data data(model);
  for (const std::string & name : names)
  {
    const char * n = name.c_str();
    if (name == "tau")
      print(n, 0, rnea(model, data, q, v, a));
    else if (name == "fd")
      print(n, 0, aba(model, data, q, v, tau));
    else if (name == "M" || name == "Minv")
    {
      Eigen::MatrixXd m = name == "M" ? Eigen::MatrixXd(crba(model, data, q))
                                      : Eigen::MatrixXd(computeMinverse(model, data, q));
      mirror_upper(m);
      print(n, 0, m);
    }
    else if (name == "tau_derivatives" || name == "fd_derivatives")
    {
      Eigen::MatrixXd d_dq = Eigen::MatrixXd::Zero(nv, nv), d_dv = Eigen::MatrixXd::Zero(nv, nv),
                      d_dx = Eigen::MatrixXd::Zero(nv, nv);
      if (name == "tau_derivatives")
        computeRNEADerivatives(model, data, q, v, a, d_dq, d_dv, d_dx);
      else
      {
        computeABADerivatives(model, data, q, v, tau, d_dq, d_dv, d_dx);
        mirror_upper(d_dx); // Minv: Pinocchio fills the upper triangle
      }
      print(n, 0, d_dq);
      print(n, 1, d_dv);
      if (name == "fd_derivatives")
        print(n, 2, d_dx);
    }
    else
    {
      std::fprintf(stderr, "unknown function %s\n", n);
      return 2;
    }
  }
  return 0;
}

int main(int argc, char ** argv)
{
  if (argc == 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h"))
  {
    std::printf(USAGE, argv[0], argv[0]);
    return 0;
  }
  const std::string mode = argc > 1 ? argv[1] : "";
  if (argc < 5 || (mode != "generate" && mode != "reference"))
  {
    std::fprintf(stderr, USAGE, argv[0], argv[0]);
    return 2;
  }
  const std::string path = argv[2];
  Model model;
  try
  {
    if (path.size() > 4 && path.substr(path.size() - 4) == ".txt")
    {
      FrameIndex flange;
      if (!read_dh_model(path.c_str(), model, flange))
        throw std::runtime_error("not a DH model file");
    }
    else
      model.loadFromBinary(path);
  }
  catch (const std::exception & e)
  {
    std::fprintf(stderr, "cannot load %s: %s\n", path.c_str(), e.what());
    return 1;
  }
  const std::vector<std::string> names(argv + 4, argv + argc);
  try
  {
    return mode == "generate" ? generate(model, argv[3], names) : reference(model, argv[3], names);
  }
  catch (const std::exception & e) // CppADCodeGen's CGException, a file that cannot be written
  {
    std::fprintf(stderr, "%s failed: %s\n", mode.c_str(), e.what());
    return 1;
  }
}
