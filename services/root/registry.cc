#include "registry.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "daemon.h"

namespace transtick {

bool IsWorkerFailure(const grpc::Status& s) {
  return s.error_code() == grpc::StatusCode::UNAVAILABLE ||
         s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED ||
         s.error_code() == grpc::StatusCode::CANCELLED;
}

namespace {

// How often the registry's clock looks, and the gap between looks that
// means the root did not run.
constexpr auto kLook = std::chrono::milliseconds(100);
constexpr auto kStall = std::chrono::seconds(1);

}  // namespace

Registry::Registry(std::chrono::milliseconds expiry)
    : expiry_(expiry), last_look_(std::chrono::steady_clock::now()), clock_(kLook, [this] {
        absl::MutexLock lock(&mu_);
        LookLocked(std::chrono::steady_clock::now());
      }) {}

void Registry::LookLocked(std::chrono::steady_clock::time_point now) {
  const auto gap = now - last_look_;
  last_look_ = now;
  if (gap <= kStall || last_seen_.empty()) return;
  spdlog::warn(
      "the root did not run for {} ms (paused, or its machine stalled); its workers' "
      "silence is counted without that time",
      std::chrono::duration_cast<std::chrono::milliseconds>(gap).count());
  for (auto& [id, seen] : last_seen_) seen = std::min(now, seen + gap);
}

absl::Status Registry::Register(const v1::RegisterRequest& req) {
  if (req.id().empty() || req.address().empty()) {
    return absl::InvalidArgumentError("Register: a worker needs an id and an address");
  }
  if (req.threads() < 0 || req.threads() > 4096) {
    return absl::InvalidArgumentError("Register: absurd thread count");
  }
  if (!(req.cpus() >= 0 && req.cpus() <= 65536) || req.machine_cpus() < 0 ||
      req.machine_cpus() > 65536) {
    return absl::InvalidArgumentError("Register: absurd CPU count");
  }
  if (req.machine().size() > 64 || !std::all_of(req.machine().begin(), req.machine().end(),
                                                [](char c) { return c > ' ' && c < 127; })) {
    return absl::InvalidArgumentError(
        "Register: the machine id is at most 64 printable characters");
  }
  absl::MutexLock lock(&mu_);
  ExpireLocked();
  if (auto it = workers_.find(req.id()); it != workers_.end()) {
    // The worker's heartbeat: the same worker at the same address.
    if (it->second->address == req.address())
      last_seen_[req.id()] = std::chrono::steady_clock::now();
    return absl::AlreadyExistsError(
        absl::StrCat("worker ", req.id(), " is already registered (at ", it->second->address, ")"));
  }
  // A worker restarted at the same address replaces its old entry.
  for (auto it = workers_.begin(); it != workers_.end();) {
    if (it->second->address == req.address()) {
      spdlog::info("worker {} at {} replaces {}", req.id(), req.address(), it->first);
      held_.erase(it->first);
      last_seen_.erase(it->first);
      it = workers_.erase(it);
    } else {
      ++it;
    }
  }
  auto w = std::make_shared<WorkerEntry>();
  w->id = req.id();
  w->address = req.address();
  w->threads = std::max(1, req.threads());
  w->memory_bytes = req.memory_bytes();
  w->memory_shared = req.memory_shared();
  w->machine = req.machine();
  w->cpus = req.cpus();
  w->machine_cpus = req.machine_cpus();
  w->order = next_order_++;
  w->channel = MakeChannel(w->address, Role::kWorker);
  w->stub = v1::Worker::NewStub(w->channel);
  workers_[w->id] = w;
  last_seen_[w->id] = std::chrono::steady_clock::now();
  spdlog::info("worker {} registered at {} ({} threads); {} workers", w->id, w->address, w->threads,
               workers_.size());
  return absl::OkStatus();
}

absl::Status Registry::Unregister(const std::string& id) {
  absl::MutexLock lock(&mu_);
  held_.erase(id);
  last_seen_.erase(id);
  if (workers_.erase(id) == 0) {
    return absl::NotFoundError(absl::StrCat("worker ", id, " is not registered"));
  }
  spdlog::info("worker {} unregistered; {} workers", id, workers_.size());
  return absl::OkStatus();
}

void Registry::Drop(const std::string& id, const std::string& why,
                    std::chrono::milliseconds recheck) {
  std::shared_ptr<WorkerEntry> w;
  {
    absl::MutexLock lock(&mu_);
    if (auto it = workers_.find(id); it != workers_.end()) w = it->second;
  }
  if (w == nullptr) return;
  if (w->channel != nullptr && w->channel->GetState(false) != GRPC_CHANNEL_READY &&
      w->channel->WaitForConnected(std::chrono::system_clock::now() + recheck)) {
    spdlog::warn("worker {} at {} failed a call ({}) but took a new connection: it stays", id,
                 w->address, why);
    return;
  }
  absl::MutexLock lock(&mu_);
  // Not one that registered anew under the id while this one was tried.
  if (auto it = workers_.find(id); it == workers_.end() || it->second != w) return;
  held_.erase(id);
  last_seen_.erase(id);
  workers_.erase(id);
  spdlog::warn("dropping worker {}: {}; {} workers left", id, why, workers_.size());
}

absl::StatusOr<std::vector<std::shared_ptr<WorkerEntry>>> Registry::Workers(
    std::chrono::milliseconds wait, const std::function<bool()>& cancelled) {
  std::vector<std::shared_ptr<WorkerEntry>> out;
  {
    absl::MutexLock lock(&mu_);
    const auto until = std::chrono::steady_clock::now() + wait;
    ExpireLocked();
    while (workers_.empty()) {
      if (cancelled()) return absl::CancelledError("cancelled");
      if (std::chrono::steady_clock::now() >= until) {
        return absl::UnavailableError(absl::StrCat(
            "no worker registered within ", std::chrono::duration<double>(wait).count(), " s"));
      }
      auto registered = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return !workers_.empty(); };
      mu_.AwaitWithTimeout(absl::Condition(&registered), absl::Milliseconds(100));
    }
    if (cancelled()) return absl::CancelledError("cancelled");
    for (auto& [id, w] : workers_) out.push_back(w);
  }
  std::sort(out.begin(), out.end(), [](auto& a, auto& b) { return a->order < b->order; });
  return out;
}

void Registry::ExpireLocked() {
  const auto now = std::chrono::steady_clock::now();
  // Whichever thread runs first after a pause sees the gap, the clock or a
  // frame's watchdog asking whether a worker is alive.
  LookLocked(now);
  for (auto it = workers_.begin(); it != workers_.end();) {
    auto seen = last_seen_.find(it->first);
    if (seen != last_seen_.end() && now - seen->second <= expiry_) {
      ++it;
      continue;
    }
    spdlog::warn(
        "dropping worker {} at {}: not heard from for {} ms; {} workers left", it->first,
        it->second->address,
        seen == last_seen_.end()
            ? -1
            : std::chrono::duration_cast<std::chrono::milliseconds>(now - seen->second).count(),
        workers_.size() - 1);
    held_.erase(it->first);
    if (seen != last_seen_.end()) last_seen_.erase(seen);
    it = workers_.erase(it);
  }
}

bool Registry::Alive(const std::string& id) {
  absl::MutexLock lock(&mu_);
  ExpireLocked();
  return workers_.count(id) > 0;
}

int Registry::size() const {
  absl::MutexLock lock(&mu_);
  return static_cast<int>(workers_.size());
}

bool Registry::AllOn(const std::string& machine) const {
  if (machine.empty()) return false;
  absl::MutexLock lock(&mu_);
  for (const auto& [id, w] : workers_) {
    if (w->machine != machine) return false;
  }
  return true;
}

std::map<std::string, HeldSlab> Registry::Held() const {
  absl::MutexLock lock(&mu_);
  return held_;
}

void Registry::SetHeld(const std::string& id, const HeldSlab& slab) {
  absl::MutexLock lock(&mu_);
  if (workers_.count(id)) held_[id] = slab;
}

void Registry::ClearHeld(const std::string& id) {
  absl::MutexLock lock(&mu_);
  held_.erase(id);
}

void Registry::Describe(v1::StatusReply* reply) {
  absl::MutexLock lock(&mu_);
  ExpireLocked();
  std::vector<std::shared_ptr<WorkerEntry>> ws;
  for (auto& [id, w] : workers_) ws.push_back(w);
  std::sort(ws.begin(), ws.end(), [](auto& a, auto& b) { return a->order < b->order; });
  for (auto& w : ws) {
    v1::WorkerInfo* info = reply->add_workers();
    info->set_id(w->id);
    info->set_address(w->address);
    info->set_threads(w->threads);
    info->set_memory_bytes(w->memory_bytes);
    info->set_memory_shared(w->memory_shared);
    info->set_machine(w->machine);
    info->set_cpus(w->cpus);
    info->set_machine_cpus(w->machine_cpus);
    auto held = held_.find(w->id);
    info->set_ring(held == held_.end() ? -1 : held->second.ring);
    if (held != held_.end()) {
      info->set_slab_begin(held->second.y0);
      info->set_slab_end(held->second.y1);
    }
  }
}

}  // namespace transtick
