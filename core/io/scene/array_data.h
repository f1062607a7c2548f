// A dense array passed alongside a scene dictionary (numpy arrays from Python). In the dictionary
// it is referenced as {"__limn_array__": index}.
#pragma once
#include <cstddef>
#include <vector>

namespace limn {

struct ArrayData {
  std::vector<size_t> shape;
  std::vector<double> values;  // row-major
  bool integer = false;
};

}  // namespace limn
