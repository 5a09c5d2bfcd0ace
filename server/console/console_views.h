// The console's JSON views that the gRPC API has no call for: each function authenticates the
// caller of `authorization` (the HTTP header) with the server's tokens, reads the server's state
// through core's objects, and answers JSON (or an image), or {"code", "message"} with the HTTP
// status of the gRPC code. The shapes are in docs/server.md, "Console".
#pragma once

#include <string>

#include "server/console/live_sampler.h"
#include "server/console/rpc_gateway.h"
#include "server/services/server_state.h"

namespace recog::server {

// GET /api/whoami: {"auth_required", "authenticated", "name", "can_read", "can_write"}.
HttpReply WhoAmIView(const ServerState& state, const std::string& authorization);
// GET /api/maps: ListMaps through the gateway (every page), each map with its disk_bytes,
// thumbnails and loops_kept.
HttpReply MapsView(const ServerState& state, const RpcGateway& gateway,
                   const std::string& authorization);
// GET /api/maps/<map>/loops: the map's recent loops (RecentLoops), newest first.
HttpReply LoopsView(const ServerState& state, const std::string& authorization,
                    const std::string& map);
// GET /api/maps/<map>/frames/<frame>/thumbnail: image/jpeg, with the frame's own size in the
// headers X-Frame-Width and X-Frame-Height.
HttpReply ThumbnailView(const ServerState& state, const std::string& authorization,
                        const std::string& map, const std::string& frame);
// GET /api/models/<name>: its ModelInfo, training views (name, camera, pose, has_image) and the
// bounds of its points.
HttpReply ModelView(const ServerState& state, const std::string& authorization,
                    const std::string& name);
// GET /api/models/<name>/points?max=N: its 3D points (evenly subsampled to at most N, default
// 20000, 1..1000000) and how many descriptors each carries.
HttpReply ModelPointsView(const ServerState& state, const std::string& authorization,
                          const std::string& name, const std::string& max);
// GET /api/models/<name>/views/<index>/image: image/png of a training view.
HttpReply ModelImageView(const ServerState& state, const std::string& authorization,
                         const std::string& name, const std::string& index);
// GET /api/charts: the charts of console.charts_dir (each x.json that has its x.png beside it,
// as WritePlot writes them, tools/evaluation/plot.h), by name: {"configured", "charts": [{"name",
// "file", "modified_unix_ms", "chart"}], "errors": [{"file", "message"}]} (a file that is not such
// a chart, or too large, is listed in errors; at most kMaxCharts files are read, and the errors say
// how many were not).
inline constexpr size_t kMaxCharts = 200;
inline constexpr uintmax_t kMaxChartBytes = 4 << 20;
HttpReply ChartsView(const ServerState& state, const std::string& authorization);
// GET /api/live: the sampler's samples, oldest first.
HttpReply LiveView(const ServerState& state, const LiveSampler& live,
                   const std::string& authorization);

}  // namespace recog::server
