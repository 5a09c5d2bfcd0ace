// Request ids of the client's mutating calls (proto/recognition/v1/place.proto, "Retries"): a
// random UUID v4 per call, so that the server answers gRPC's retries of the call (which resend the
// same message) with the first attempt's result instead of applying it twice. Internal to the
// client library.
#pragma once

#include <string>

namespace recog::client::internal {

// A fresh random UUID v4 in its canonical form, 36 lowercase characters
// ("xxxxxxxx-xxxx-4xxx-[89ab]xxx-xxxxxxxxxxxx"), from a per-thread generator seeded by
// std::random_device. Thread-safe.
std::string NewRequestId();

// `given` when it is not empty (the caller's own id), else NewRequestId().
std::string RequestIdOr(const std::string& given);

}  // namespace recog::client::internal
