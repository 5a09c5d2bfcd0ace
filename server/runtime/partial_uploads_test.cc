// PartialUploads: interrupted uploads kept and taken out, completed uploads remembered, expiry,
// the byte and entry bounds.
#include "server/runtime/partial_uploads.h"

#include <gtest/gtest.h>

namespace recog::server {
namespace {

using std::chrono::minutes;
using Key = PartialUploads::Key;

const PartialUploads::Clock::time_point kStart{};

TEST(PartialUploadsTest, InterruptedBytesAreReportedThenTakenOutOnce) {
  PartialUploads uploads(1000, minutes(30));
  const Key key{"aa", 100};
  EXPECT_EQ(uploads.ProgressOf(key, kStart).received_bytes, 0u);
  uploads.KeepInterrupted(key, std::string(40, 'x'), kStart);
  const PartialUploads::Progress progress = uploads.ProgressOf(key, kStart);
  EXPECT_EQ(progress.received_bytes, 40u);
  EXPECT_FALSE(progress.stored.has_value());
  EXPECT_EQ(uploads.ProgressOf({"aa", 101}, kStart).received_bytes, 0u);  // another file
  std::optional<std::string> taken = uploads.TakeInterrupted(key, kStart);
  ASSERT_TRUE(taken.has_value());
  EXPECT_EQ(*taken, std::string(40, 'x'));
  EXPECT_FALSE(uploads.TakeInterrupted(key, kStart).has_value());
  EXPECT_EQ(uploads.kept_bytes(), 0u);
}

TEST(PartialUploadsTest, NothingIsKeptOfAnEmptyOrWholeOrOversizedPrefix) {
  PartialUploads uploads(50, minutes(30));
  uploads.KeepInterrupted({"aa", 100}, "", kStart);
  uploads.KeepInterrupted({"bb", 10}, std::string(10, 'x'), kStart);   // the whole file
  uploads.KeepInterrupted({"cc", 100}, std::string(60, 'x'), kStart);  // over max_bytes
  EXPECT_EQ(uploads.kept_bytes(), 0u);
  EXPECT_EQ(uploads.ProgressOf({"cc", 100}, kStart).received_bytes, 0u);
}

TEST(PartialUploadsTest, ACompletedUploadIsRememberedInsteadOfItsBytes) {
  PartialUploads uploads(1000, minutes(30));
  const Key key{"aa", 100};
  uploads.KeepInterrupted(key, std::string(40, 'x'), kStart);
  uploads.RecordStored(key, {"poster", 3}, kStart + minutes(1));
  const PartialUploads::Progress progress = uploads.ProgressOf(key, kStart + minutes(2));
  EXPECT_EQ(progress.received_bytes, 0u);
  ASSERT_TRUE(progress.stored.has_value());
  EXPECT_EQ(progress.stored->name, "poster");
  EXPECT_EQ(progress.stored->version, 3u);
  EXPECT_EQ(uploads.kept_bytes(), 0u);
  EXPECT_FALSE(uploads.TakeInterrupted(key, kStart + minutes(2)).has_value());
}

TEST(PartialUploadsTest, EntriesAreForgottenAfterKeepFor) {
  PartialUploads uploads(1000, minutes(30));
  uploads.KeepInterrupted({"aa", 100}, std::string(40, 'x'), kStart);
  uploads.RecordStored({"bb", 100}, {"poster", 1}, kStart + minutes(10));
  EXPECT_EQ(uploads.ProgressOf({"aa", 100}, kStart + minutes(29)).received_bytes, 40u);
  EXPECT_EQ(uploads.ProgressOf({"aa", 100}, kStart + minutes(30)).received_bytes, 0u);
  EXPECT_EQ(uploads.kept_bytes(), 0u);
  EXPECT_TRUE(uploads.ProgressOf({"bb", 100}, kStart + minutes(39)).stored.has_value());
  EXPECT_FALSE(uploads.ProgressOf({"bb", 100}, kStart + minutes(40)).stored.has_value());
}

TEST(PartialUploadsTest, TheOldestBytesMakeRoomForNewOnes) {
  PartialUploads uploads(100, minutes(30));
  uploads.KeepInterrupted({"aa", 1000}, std::string(60, 'a'), kStart);
  uploads.KeepInterrupted({"bb", 1000}, std::string(30, 'b'), kStart + minutes(1));
  uploads.KeepInterrupted({"cc", 1000}, std::string(50, 'c'), kStart + minutes(2));
  EXPECT_EQ(uploads.ProgressOf({"aa", 1000}, kStart + minutes(2)).received_bytes, 0u);
  EXPECT_EQ(uploads.ProgressOf({"bb", 1000}, kStart + minutes(2)).received_bytes, 30u);
  EXPECT_EQ(uploads.ProgressOf({"cc", 1000}, kStart + minutes(2)).received_bytes, 50u);
  EXPECT_EQ(uploads.kept_bytes(), 80u);
  // Keeping bytes of an upload again replaces its earlier bytes.
  uploads.KeepInterrupted({"bb", 1000}, std::string(45, 'b'), kStart + minutes(3));
  EXPECT_EQ(uploads.kept_bytes(), 95u);
}

TEST(PartialUploadsTest, AtMostMaxEntriesAreRemembered) {
  PartialUploads uploads(1000, minutes(30));
  for (size_t i = 0; i <= PartialUploads::kMaxEntries; ++i) {
    uploads.RecordStored({std::to_string(i), 100}, {"m", uint32_t(i + 1)},
                         kStart + std::chrono::milliseconds(i));
  }
  const auto now = kStart + minutes(1);
  EXPECT_FALSE(uploads.ProgressOf({"0", 100}, now).stored.has_value());  // the oldest went
  EXPECT_TRUE(uploads.ProgressOf({"1", 100}, now).stored.has_value());
  EXPECT_TRUE(uploads.ProgressOf({std::to_string(PartialUploads::kMaxEntries), 100}, now)
                  .stored.has_value());
}

}  // namespace
}  // namespace recog::server
