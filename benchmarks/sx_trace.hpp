// What the CasADi tracers of Pinocchio (pinocchio_casadi_trace.cpp, pinocchio_tree_trace.cpp)
// share: Pinocchio on casadi::SX, symbolic inputs seen from both sides, and saving a traced
// graph as a named casadi::Function. Include it before any other Pinocchio header.
#ifndef KDG_SX_TRACE_HPP
#define KDG_SX_TRACE_HPP

#include <pinocchio/autodiff/casadi.hpp> // must precede the other Pinocchio headers

#include <string>
#include <utility>
#include <vector>

using SX = ::casadi::SX;
using ADModel = pinocchio::ModelTpl<SX>;
using ADData = pinocchio::DataTpl<SX>;
using VectorXs = Eigen::Matrix<SX, Eigen::Dynamic, 1>;
using MatrixXs = Eigen::Matrix<SX, Eigen::Dynamic, Eigen::Dynamic>;
using Port = std::pair<std::string, SX>;

// A symbolic input: the CasADi column vector and the same symbols as an Eigen vector.
struct Symbol
{
  SX sx;
  VectorXs eigen;
};

static Symbol symbol(const std::string & name, int n)
{
  Symbol s{SX::sym(name, n), VectorXs(n)};
  for (int i = 0; i < n; ++i)
    s.eigen[i] = s.sx(i);
  return s;
}

template<typename Derived>
static SX to_sx(const Eigen::MatrixBase<Derived> & m)
{
  SX out;
  pinocchio::casadi::copy(m, out);
  return out;
}

// Saves the Function `name` (named inputs and outputs) to `path`.
static void save_function(const std::string & path, const std::string & name, const std::vector<Port> & inputs,
                          const std::vector<Port> & outputs)
{
  std::vector<SX> in, out;
  std::vector<std::string> in_names, out_names;
  for (const Port & p : inputs)
  {
    in_names.push_back(p.first);
    in.push_back(p.second);
  }
  for (const Port & p : outputs)
  {
    out_names.push_back(p.first);
    out.push_back(p.second);
  }
  // cse: the traced graph repeats sub-expressions (the same spatial products are formed in
  // several places); merging them is one option away, and a user after speed would set it.
  const ::casadi::Dict options{{"cse", true}};
  ::casadi::Function(name, in, out, in_names, out_names, options).save(path);
}

#endif
