// Median: the middle of a sample (timings, errors), as the evaluations and benchmarks summarise
// it.
#pragma once

#include <vector>

namespace recog {

// The median of the values: the middle one of an odd count, the mean of the two middle ones of an
// even count; 0 for none. Takes a copy, which it reorders.
double Median(std::vector<double> values);

}  // namespace recog
