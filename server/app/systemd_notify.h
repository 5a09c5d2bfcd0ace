// NotifySystemd: readiness and state notifications to the service manager (systemd's
// Type=notify), the documented sd_notify(3) datagram protocol without linking libsystemd.
//
// When the environment variable NOTIFY_SOCKET names a unix datagram socket (a path, or "@name"
// for an abstract one), NotifySystemd sends `state` ("READY=1", "RELOADING=1", "STOPPING=1",
// "STATUS=...", newline-separated assignments) to it; without NOTIFY_SOCKET it does nothing. A
// socket that cannot be reached is not an error of the server: the failure is returned for the
// caller to log. Thread-safe.
#pragma once

#include <string_view>

#include "core/common/status.h"

namespace recog::server {

// OK when sent or when NOTIFY_SOCKET is unset; UNAVAILABLE naming the socket otherwise.
Status NotifySystemd(std::string_view state);

}  // namespace recog::server
