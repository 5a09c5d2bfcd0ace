// The metadata headers by which a router in front of sharded recogd servers (nginx,
// deploy/nginx/) sends a call to the right shard: the clients add them, nginx reads them, recogd
// ignores them (it checks ownership from the request itself, server/config/placement_table.h).
#pragma once

namespace recog {

// The place map a call is about: CreateMap, GetMap, DeleteMap, AddFrame, QueryPlace, StreamFrames,
// RemoveFrame.
inline constexpr char kMapHeader[] = "x-recog-map";
// The shard a call without a map is meant for (ListMaps through a router); optional otherwise.
inline constexpr char kShardHeader[] = "x-recog-shard";

}  // namespace recog
