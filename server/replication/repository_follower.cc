#include "server/replication/repository_follower.h"

#include <algorithm>
#include <filesystem>
#include <map>
#include <set>

#include <spdlog/spdlog.h>

#include "core/common/file_io.h"
#include "server/api/object_converters.h"
#include "wire/grpc_code_names.h"

namespace recog::server {
namespace {

namespace pb = ::recognition::v1;

// A failure on the primary's side, for the log: "<what>: CODE: message".
Status PrimaryError(const std::string& what, const grpc::Status& status) {
  return Status::Unavailable(what + ": " + std::string(GrpcCodeName(status.error_code())) + ": " +
                             status.error_message());
}

// True when `local` (oldest first) is the first local.size() versions of `primary`.
bool IsPrefixOf(const std::vector<ModelVersionInfo>& local,
                const std::vector<pb::ModelInfo>& primary) {
  if (local.size() > primary.size()) return false;
  for (size_t i = 0; i < local.size(); ++i) {
    if (local[i].metadata.version != primary[i].version() ||
        local[i].sha256 != primary[i].sha256()) {
      return false;
    }
  }
  return true;
}

}  // namespace

StatusOr<std::unique_ptr<RepositoryFollower>> RepositoryFollower::Start(Options options,
                                                                        ServerState* state) {
  if (options.staging_dir.empty()) {
    return Status::InvalidArgument("a repository follower needs a staging directory");
  }
  std::error_code error;
  std::filesystem::create_directories(options.staging_dir, error);
  if (error) {
    return Status::FailedPrecondition("cannot create the staging directory '" +
                                      options.staging_dir + "': " + error.message());
  }
  client::Result<std::unique_ptr<client::RecognitionClient>> primary =
      client::RecognitionClient::Connect(options.primary);
  if (!primary.ok()) {
    return Status::InvalidArgument("repository: cannot follow '" + options.primary.target +
                                   "': " + primary.status().error_message());
  }
  return std::unique_ptr<RepositoryFollower>(
      new RepositoryFollower(std::move(options), std::move(*primary), state));
}

RepositoryFollower::RepositoryFollower(Options options,
                                       std::unique_ptr<client::RecognitionClient> primary,
                                       ServerState* state)
    : options_(std::move(options)),
      primary_(std::move(primary)),
      state_(*state),
      repository_(*state->repository),
      thread_([this] { Run(); }) {}

RepositoryFollower::~RepositoryFollower() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  thread_.join();
}

void RepositoryFollower::Run() {
  spdlog::info("repository: following the primary at {}", options_.primary.target);
  std::chrono::milliseconds delay = options_.min_retry_delay;
  while (true) {
    const Status ended = FollowOnce();
    const bool had_synced = synced_;
    SetSynced(false);
    std::unique_lock lock(mutex_);
    if (stopping_) return;
    if (had_synced) delay = options_.min_retry_delay;
    spdlog::warn("repository: following {} stopped ({}); watching again in {} ms",
                 options_.primary.target, ended.ToString(), delay.count());
    changed_.wait_for(lock, delay, [this] { return stopping_; });
    if (stopping_) return;
    if (!had_synced) delay = std::min(delay * 2, options_.max_retry_delay);
  }
}

Status RepositoryFollower::FollowOnce() {
  {
    std::lock_guard lock(mutex_);
    events_.clear();
    watch_ended_.reset();
  }
  std::unique_ptr<client::ModelWatch> watch = primary_->WatchModels(
      "",
      [this](const pb::WatchModelsResponse& event) {
        {
          std::lock_guard lock(mutex_);
          events_.push_back(event);
        }
        changed_.notify_all();
      },
      /*include_existing=*/true,
      [this](const grpc::Status& status) {
        {
          std::lock_guard lock(mutex_);
          watch_ended_ = status.ok() ? Status::Unavailable("the primary ended the watch")
                                     : PrimaryError("the watch", status);
        }
        changed_.notify_all();
      });
  std::vector<pb::ModelInfo> primary_versions;  // until SYNCED
  Status ended;
  while (std::optional<pb::WatchModelsResponse> event = NextEvent(&ended)) {
    Status applied;
    if (synced_) {
      applied = Apply(*event);
    } else if (event->change() == pb::MODEL_CHANGE_PUT) {
      primary_versions.push_back(event->model());
    } else if (event->change() == pb::MODEL_CHANGE_SYNCED) {
      applied = Sync(primary_versions);
      primary_versions = {};
      if (applied.ok()) SetSynced(true);
    } else {
      applied = Status::Internal("the primary sent change " + std::to_string(event->change()) +
                                 " before MODEL_CHANGE_SYNCED");
    }
    if (!applied.ok()) return applied;  // the watch is cancelled as it goes
  }
  return ended;
}

std::optional<pb::WatchModelsResponse> RepositoryFollower::NextEvent(Status* ended) {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [this] { return stopping_ || !events_.empty() || watch_ended_.has_value(); });
  if (stopping_) {
    *ended = Status::Unavailable("the server is stopping");
    return std::nullopt;
  }
  if (events_.empty()) {
    *ended = *watch_ended_;
    return std::nullopt;
  }
  pb::WatchModelsResponse event = std::move(events_.front());
  events_.pop_front();
  return event;
}

Status RepositoryFollower::Sync(const std::vector<pb::ModelInfo>& primary_versions) {
  std::map<std::string, std::vector<pb::ModelInfo>> primary_models;
  for (const pb::ModelInfo& version : primary_versions) {
    primary_models[version.name()].push_back(version);
  }
  // Local models the primary does not have.
  std::string page_token;
  std::set<std::string> local_names;
  do {
    RECOG_ASSIGN_OR_RETURN(ModelPage page,
                           repository_.List({}, ModelRepository::kMaxPageSize, page_token));
    for (const ModelVersionInfo& info : page.models) local_names.insert(info.metadata.name);
    page_token = page.next_page_token;
  } while (!page_token.empty());
  for (const std::string& name : local_names) {
    if (!primary_models.contains(name)) RECOG_RETURN_IF_ERROR(RemoveLocal(name));
  }
  size_t copied = 0;
  for (const auto& [name, versions] : primary_models) {
    std::vector<ModelVersionInfo> local = repository_.Versions(name);
    if (!IsPrefixOf(local, versions)) {
      spdlog::info("repository: model '{}' differs from the primary's; copying it anew", name);
      RECOG_RETURN_IF_ERROR(RemoveLocal(name));
      local.clear();
    }
    for (size_t i = local.size(); i < versions.size(); ++i) {
      if (Stopping()) return Status::Unavailable("the server is stopping");
      RECOG_RETURN_IF_ERROR(Copy(versions[i]));
      ++copied;
    }
  }
  spdlog::info("repository: synced with {}: {} models, {} versions copied", options_.primary.target,
               primary_models.size(), copied);
  return Status::Ok();
}

Status RepositoryFollower::Apply(const pb::WatchModelsResponse& change) {
  const pb::ModelInfo& version = change.model();
  if (change.change() == pb::MODEL_CHANGE_DELETED) {
    const Status removed = RemoveLocal(version.name());
    return removed.code() == StatusCode::kNotFound ? Status::Ok() : removed;
  }
  if (change.change() != pb::MODEL_CHANGE_PUT) {
    return Status::Internal("the primary sent change " + std::to_string(change.change()) +
                            " after MODEL_CHANGE_SYNCED");
  }
  const std::vector<ModelVersionInfo> local = repository_.Versions(version.name());
  if (!local.empty() && local.back().metadata.version >= version.version()) {
    // Only a stream that skipped a deletion could get here; follow the primary all the same.
    spdlog::warn("repository: model '{}' has version {} here, the primary sends {}; replacing it",
                 version.name(), local.back().metadata.version, version.version());
    RECOG_RETURN_IF_ERROR(RemoveLocal(version.name()));
  }
  return Copy(version);
}

Status RepositoryFollower::Copy(const pb::ModelInfo& version) {
  const std::filesystem::path path = std::filesystem::path(options_.staging_dir) /
                                     (version.name() + "." + std::to_string(version.version()));
  client::Result<pb::ModelInfo> downloaded =
      primary_->DownloadModel(version.name(), version.version(), path.string());
  if (downloaded.status().error_code() == grpc::StatusCode::NOT_FOUND) {
    spdlog::info("repository: version {} of '{}' is gone from the primary; skipped",
                 version.version(), version.name());
    return Status::Ok();
  }
  if (!downloaded.ok()) {
    return PrimaryError(
        "downloading version " + std::to_string(version.version()) + " of '" + version.name() + "'",
        downloaded.status());
  }
  StatusOr<std::string> file =
      ReadWholeFile(path.string(), "downloaded model '" + path.string() + "'");
  std::error_code error;
  std::filesystem::remove(path, error);
  RECOG_RETURN_IF_ERROR(file.status());
  RECOG_RETURN_IF_ERROR(repository_.PutCopy(FromProto(*downloaded), *file).status());
  state_.metrics.AddReplicaChanges();
  state_.metrics.SetObjects(state_.objects->size());
  spdlog::info("repository: copied version {} of '{}' from the primary", version.version(),
               version.name());
  return Status::Ok();
}

Status RepositoryFollower::RemoveLocal(const std::string& name) {
  RECOG_RETURN_IF_ERROR(repository_.Remove(name));
  state_.metrics.AddReplicaChanges();
  state_.metrics.SetObjects(state_.objects->size());
  spdlog::info("repository: removed model '{}' as the primary did", name);
  return Status::Ok();
}

bool RepositoryFollower::Stopping() {
  std::lock_guard lock(mutex_);
  return stopping_;
}

void RepositoryFollower::SetSynced(bool synced) {
  synced_ = synced;
  state_.metrics.SetReplicaSynced(synced);
}

}  // namespace recog::server
