// RequestLog: the answers of recent mutating calls, by the request id their client chose, so that
// a call sent again (a retry after a lost answer) is answered with the first call's result
// instead of being applied twice.
//
// Callers compose the key (the server uses caller, method and request id) and pass a digest of
// the request beside it, so that a key reused for another request is told apart from a repeat.
// The contract:
//  - Begin(key) says kRun for a key it does not hold: the caller runs the call and then calls
//    End(key, answer) exactly once. A successful call's answer (the serialised response) is
//    remembered for `window` after End; a failed call's is not (nullopt), so a repeat of a failed
//    call runs again.
//  - Begin(key) of a remembered key says kRepeat with the stored answer: the caller answers with
//    it and changes nothing.
//  - Begin(key) with another digest than the call that holds the key (running or remembered)
//    says kConflict at once: the client reused its request id for a different request, which
//    must neither run as a repeat nor be answered with another request's answer.
//  - Begin(key) while another call with the key runs waits for that call to end (until
//    `wait_until`): then kRepeat with its answer, or kRun when it failed, or kTimedOut when it
//    was still running at `wait_until`. So a duplicate never runs beside the first.
// At most `capacity` answers are remembered, the oldest forgotten first (calls still running are
// not counted); capacity 0 remembers nothing and never waits (every Begin says kRun). Memory only:
// a restarted server has forgotten every answer. Thread-safe. Times are passed in (steady clock)
// so that expiry can be tested.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <list>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>

namespace recog::server {

class RequestLog {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr size_t kMaxRequestIdBytes = 128;
  static constexpr Clock::duration kWindow = std::chrono::minutes(10);

  // What Begin decided.
  struct Claim {
    enum class Kind {
      kRun,       // run the call, then End(key, ...)
      kRepeat,    // answer with `answer`, change nothing
      kTimedOut,  // a call with the same key was still running at wait_until
      kConflict,  // the key is held by a different request (another digest)
    };
    Kind kind = Kind::kRun;
    std::string answer;  // kRepeat: the stored answer
  };

  explicit RequestLog(size_t capacity, Clock::duration window = kWindow);

  // Whether `request_id` is a valid request id: 1 to kMaxRequestIdBytes printable ASCII
  // characters (space to '~').
  static bool ValidRequestId(std::string_view request_id);

  // See the header comment. `digest` identifies the request's content; `now` is the time of the
  // call; waiting uses the steady clock.
  Claim Begin(const std::string& key, const std::string& digest, Clock::time_point now,
              Clock::time_point wait_until);
  // Ends the call that Begin(key) let run: remembers `answer` from `now` (nullopt: the call
  // failed, nothing is remembered) and wakes the duplicates waiting for it.
  void End(const std::string& key, std::optional<std::string> answer, Clock::time_point now);

  // Answers remembered (for tests).
  size_t size() const;

 private:
  struct Entry {
    bool running = true;
    std::string digest;  // of the request that holds the key
    std::string answer;
    Clock::time_point stored_at;
    std::list<std::string>::iterator order;  // in order_, once stored
  };
  // Forgets the answers older than window_, then the oldest until at most capacity_ remain.
  void ExpireLocked(Clock::time_point now);

  const size_t capacity_;
  const Clock::duration window_;
  mutable std::mutex mutex_;
  std::condition_variable ended_;  // notified by End
  std::unordered_map<std::string, Entry> entries_;
  std::list<std::string> order_;  // keys of the stored answers, oldest first
};

}  // namespace recog::server
