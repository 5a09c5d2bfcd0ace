#include "core/common/median.h"

#include <algorithm>

namespace recog {

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto middle = values.begin() + long(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  if (values.size() % 2 == 1) return *middle;
  // The other middle value is the largest of those before it.
  return (*middle + *std::max_element(values.begin(), middle)) / 2.0;
}

}  // namespace recog
