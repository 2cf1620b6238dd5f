// Frame ids from a comma-separated list of frame names (pinocchio_tree_bench.cpp,
// pinocchio_tree_trace.cpp): std::invalid_argument naming the first unknown frame.
#ifndef KDG_FRAME_LIST_HPP
#define KDG_FRAME_LIST_HPP

#include <pinocchio/multibody.hpp>

#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

static std::vector<pinocchio::FrameIndex> frame_ids(const pinocchio::Model & model, const std::string & list)
{
  std::vector<pinocchio::FrameIndex> ids;
  std::stringstream stream(list);
  std::string name;
  while (std::getline(stream, name, ','))
  {
    if (!model.existFrame(name))
      throw std::invalid_argument("no frame named " + name);
    ids.push_back(model.getFrameId(name));
  }
  return ids;
}

#endif
