// RepositoryFollower: keeps a replica's model repository equal to its primary's
// (ServerConfig::repository, docs/scaling.md).
//
// A thread of its own watches the primary's repository through the client library: WatchModels
// with include_existing, which first lists every version the primary stores, then says SYNCED,
// then streams each change as it happens. At SYNCED the follower makes the local repository equal
// to that list: it removes the models the primary does not have; of a model whose local versions
// are the primary's first ones it copies the newer versions; a model whose history differs (it
// was deleted and uploaded anew while this replica was away) is removed and copied whole. After
// that every upload is copied and every deletion applied as it arrives. A copy keeps the primary's
// version number, tags, creation time and bytes (ModelRepository::PutCopy): the file is
// downloaded, verified against its SHA-256, into `staging_dir`, stored, and deleted.
//
// When the stream ends — the primary restarts or cannot be reached, this replica fell more than
// 1024 changes behind, a copy fails — the follower logs why, waits (min_retry_delay, doubling up
// to max_retry_delay, back to the minimum after a sync) and watches anew, which syncs again from
// the primary's state. Meanwhile the replica serves what it holds. The `recog_replica_synced`
// metric is 1 while the follower is past SYNCED on a live stream.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "client/cpp/client_options.h"
#include "client/cpp/recognition_client.h"
#include "core/common/status.h"
#include "server/services/server_state.h"

namespace recog::server {

class RepositoryFollower {
 public:
  struct Options {
    // How to reach the primary (target, token file, TLS CA); its retries cover brief outages of
    // single calls, the follower's own delays cover the rest.
    client::ClientOptions primary;
    // Default "": where downloads land before they are stored (created when missing). Required.
    std::string staging_dir;
    // Default 500 ms and 30 s: the delay before watching anew after the stream ended, doubled
    // after each attempt that did not reach SYNCED.
    std::chrono::milliseconds min_retry_delay{500};
    std::chrono::milliseconds max_retry_delay{30000};
  };

  // Starts following at once, into the repository of `state` (which must be ready and outlive
  // the follower). INVALID_ARGUMENT for options the client refuses or an empty staging_dir;
  // FAILED_PRECONDITION when staging_dir cannot be created.
  static StatusOr<std::unique_ptr<RepositoryFollower>> Start(Options options, ServerState* state);
  // Stops: ends the watch, lets a copy in progress finish (a download may take up to the
  // client's transfer deadline; a sync stops between copies), joins the thread.
  ~RepositoryFollower();
  RepositoryFollower(const RepositoryFollower&) = delete;
  RepositoryFollower& operator=(const RepositoryFollower&) = delete;

  // True while the follower is past SYNCED on a live stream (as recog_replica_synced).
  bool synced() const { return synced_; }

 private:
  RepositoryFollower(Options options, std::unique_ptr<client::RecognitionClient> primary,
                     ServerState* state);

  void Run();
  // One watch: the primary's state, the sync, then the changes, until the stream ends, a change
  // cannot be applied, or the follower stops. Returns why it ended.
  Status FollowOnce();
  // Waits for the next event of the current watch; nullopt once it ended (*ended says why) or
  // the follower stops.
  std::optional<::recognition::v1::WatchModelsResponse> NextEvent(Status* ended);
  // Makes the local repository equal to the primary's versions (by name, oldest first).
  Status Sync(const std::vector<::recognition::v1::ModelInfo>& primary_versions);
  // Applies one change of the live stream.
  Status Apply(const ::recognition::v1::WatchModelsResponse& change);
  // Downloads a version from the primary and stores it as it is there. A version the primary
  // deleted meanwhile is skipped: its deletion comes next on the stream.
  Status Copy(const ::recognition::v1::ModelInfo& version);
  Status RemoveLocal(const std::string& name);
  bool Stopping();
  void SetSynced(bool synced);

  const Options options_;
  const std::unique_ptr<client::RecognitionClient> primary_;
  ServerState& state_;
  ModelRepository& repository_;
  std::atomic<bool> synced_{false};

  std::mutex mutex_;  // guards the three below
  std::condition_variable changed_;
  std::deque<::recognition::v1::WatchModelsResponse> events_;  // of the current watch
  std::optional<Status> watch_ended_;                          // of the current watch
  bool stopping_ = false;
  std::thread thread_;  // last: starts once everything above is built
};

}  // namespace recog::server
