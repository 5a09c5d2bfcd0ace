// The mapping of core statuses to gRPC statuses (server/api/status_mapping.h): every code to its
// canonical namesake, and the server's own failures (DATA_LOSS, INTERNAL) sanitised.
#include "server/api/status_mapping.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace recog::server {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

TEST(StatusMappingTest, EveryCoreCodeMapsToItsCanonicalGrpcCode) {
  const std::pair<StatusCode, grpc::StatusCode> cases[] = {
      {StatusCode::kOk, grpc::StatusCode::OK},
      {StatusCode::kInvalidArgument, grpc::StatusCode::INVALID_ARGUMENT},
      {StatusCode::kNotFound, grpc::StatusCode::NOT_FOUND},
      {StatusCode::kAlreadyExists, grpc::StatusCode::ALREADY_EXISTS},
      {StatusCode::kFailedPrecondition, grpc::StatusCode::FAILED_PRECONDITION},
      {StatusCode::kResourceExhausted, grpc::StatusCode::RESOURCE_EXHAUSTED},
      {StatusCode::kUnavailable, grpc::StatusCode::UNAVAILABLE},
      {StatusCode::kUnauthenticated, grpc::StatusCode::UNAUTHENTICATED},
      {StatusCode::kPermissionDenied, grpc::StatusCode::PERMISSION_DENIED},
      {StatusCode::kDataLoss, grpc::StatusCode::DATA_LOSS},
      {StatusCode::kInternal, grpc::StatusCode::INTERNAL},
  };
  for (const auto& [core, grpc_code] : cases) {
    EXPECT_EQ(ToGrpcCode(core), grpc_code) << int(core);
  }
}

TEST(StatusMappingTest, ClientErrorsKeepTheirMessage) {
  const grpc::Status status = ToGrpcStatus(Status::NotFound("map 'a' does not exist"), "r1");
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(status.error_message(), "map 'a' does not exist");
  EXPECT_TRUE(ToGrpcStatus(Status::Ok(), "r1").ok());
}

TEST(StatusMappingTest, CorruptionIsDataLossWithASanitisedMessageNamingTheRequest) {
  const grpc::Status status =
      ToGrpcStatus(Status::DataLoss("entry 17 of map 3: checksum mismatch in /var/lib/x"), "r42");
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DATA_LOSS);
  EXPECT_THAT(status.error_message(), HasSubstr("r42"));
  EXPECT_THAT(status.error_message(), HasSubstr("corrupt"));
  EXPECT_THAT(status.error_message(), Not(HasSubstr("/var/lib/x")));

  const grpc::Status internal = ToGrpcStatus(Status::Internal("assertion in foo.cc:12"), "r43");
  EXPECT_EQ(internal.error_code(), grpc::StatusCode::INTERNAL);
  EXPECT_THAT(internal.error_message(), HasSubstr("r43"));
  EXPECT_THAT(internal.error_message(), Not(HasSubstr("foo.cc")));
}

}  // namespace
}  // namespace recog::server
