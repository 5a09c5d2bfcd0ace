// ByteBudget: how many bytes work in progress may hold at once, shared by concurrent users: the
// unary requests recogd has taken and not yet answered (grpc.pending_requests_mb), the console's
// bodies being read and decoded. Each user reserves its bytes before it queues or allocates
// anything and holds the Reservation until done; destroying it gives them back. A reservation
// larger than what is left, or than the whole budget, is refused and charges nothing.
// Thread-safe and lock-free.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <utility>

namespace recog::server {

class ByteBudget {
 public:
  explicit ByteBudget(uint64_t total) : total_(total) {}
  ByteBudget(const ByteBudget&) = delete;
  ByteBudget& operator=(const ByteBudget&) = delete;

  // Holds its bytes until destroyed. The budget must outlive it.
  class Reservation {
   public:
    Reservation(Reservation&& other) noexcept
        : budget_(std::exchange(other.budget_, nullptr)), bytes_(other.bytes_) {}
    Reservation(const Reservation&) = delete;
    Reservation& operator=(const Reservation&) = delete;
    Reservation& operator=(Reservation&&) = delete;
    ~Reservation() {
      if (budget_ != nullptr) budget_->used_.fetch_sub(bytes_);
    }

   private:
    friend class ByteBudget;
    Reservation(ByteBudget* budget, uint64_t bytes) : budget_(budget), bytes_(bytes) {}
    ByteBudget* budget_;
    uint64_t bytes_;
  };

  // `bytes` of the budget, or nothing when fewer are left.
  std::optional<Reservation> Reserve(uint64_t bytes) {
    uint64_t used = used_.load();
    do {
      if (bytes > total_ || used > total_ - bytes) return std::nullopt;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return Reservation(this, bytes);
  }

  uint64_t used() const { return used_.load(); }
  uint64_t total() const { return total_; }

 private:
  const uint64_t total_;
  std::atomic<uint64_t> used_{0};
};

}  // namespace recog::server
