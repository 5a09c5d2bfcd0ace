// PlaceService: the PlaceRecognition RPCs (proto/recognition/v1/place.proto) over MapRegistry and
// PlaceMap.
//
// Each RPC decodes its request, makes one core call (MapRegistry for map management; for a frame
// PlaceMap::Add for AddFrame, Detect for QueryPlace with add_frame and writing streams, Query for
// QueryPlace and query-only streams; SearchMaps and Relocalize for the maps a query searches and
// Relocalize) and encodes the result, updating the metrics. Map management
// and unary frames run on the worker pool through RunUnary. StreamFrames is one reactor per call
// (FrameStream in place_service.cc) that reads a frame only after answering the previous one.
// PlaceMap orders the frames of one map and lets queries run beside them.
#pragma once

#include "recognition/v1/place.grpc.pb.h"
#include "server/services/server_state.h"

namespace recog::server {

class PlaceService final : public ::recognition::v1::PlaceRecognition::CallbackService {
 public:
  explicit PlaceService(ServerState* state) : state_(*state) {}

  grpc::ServerUnaryReactor* CreateMap(grpc::CallbackServerContext* context,
                                      const ::recognition::v1::CreateMapRequest* request,
                                      ::recognition::v1::CreateMapResponse* response) override;
  grpc::ServerUnaryReactor* GetMap(grpc::CallbackServerContext* context,
                                   const ::recognition::v1::GetMapRequest* request,
                                   ::recognition::v1::GetMapResponse* response) override;
  grpc::ServerUnaryReactor* ListMaps(grpc::CallbackServerContext* context,
                                     const ::recognition::v1::ListMapsRequest* request,
                                     ::recognition::v1::ListMapsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteMap(grpc::CallbackServerContext* context,
                                      const ::recognition::v1::DeleteMapRequest* request,
                                      ::recognition::v1::DeleteMapResponse* response) override;
  grpc::ServerUnaryReactor* AddFrame(grpc::CallbackServerContext* context,
                                     const ::recognition::v1::AddFrameRequest* request,
                                     ::recognition::v1::AddFrameResponse* response) override;
  grpc::ServerUnaryReactor* QueryPlace(grpc::CallbackServerContext* context,
                                       const ::recognition::v1::QueryPlaceRequest* request,
                                       ::recognition::v1::QueryPlaceResponse* response) override;
  grpc::ServerUnaryReactor* RemoveFrame(grpc::CallbackServerContext* context,
                                        const ::recognition::v1::RemoveFrameRequest* request,
                                        ::recognition::v1::RemoveFrameResponse* response) override;
  grpc::ServerUnaryReactor* Relocalize(grpc::CallbackServerContext* context,
                                       const ::recognition::v1::RelocalizeRequest* request,
                                       ::recognition::v1::RelocalizeResponse* response) override;
  grpc::ServerBidiReactor<::recognition::v1::StreamFramesRequest,
                          ::recognition::v1::StreamFramesResponse>*
  StreamFrames(grpc::CallbackServerContext* context) override;

 private:
  ServerState& state_;
};

}  // namespace recog::server
