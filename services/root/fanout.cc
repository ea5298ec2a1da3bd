#include "fanout.h"

#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

#include "daemon.h"

namespace transtick {

absl::Status ForEachParallel(size_t n, const std::function<absl::Status(size_t)>& fn) {
  std::vector<absl::Status> results(n);
  std::vector<std::thread> threads;
  for (size_t i = 0; i < n; ++i) threads.emplace_back([&, i] { results[i] = fn(i); });
  for (auto& t : threads) t.join();
  for (auto& s : results) {
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

std::vector<grpc::Status> CallAll(size_t n, double deadline_s, const StartCall& start) {
  std::vector<grpc::Status> results(n);
  std::deque<grpc::ClientContext> contexts(n);
  std::mutex mu;
  std::condition_variable cv;
  size_t pending = n;
  for (size_t i = 0; i < n; ++i) {
    contexts[i].set_deadline(Deadline(deadline_s));
    start(i, &contexts[i], [&, i](grpc::Status s) {
      std::lock_guard<std::mutex> lock(mu);
      results[i] = std::move(s);
      if (--pending == 0) cv.notify_all();
    });
  }
  std::unique_lock<std::mutex> lock(mu);
  cv.wait(lock, [&] { return pending == 0; });
  return results;
}

}  // namespace transtick
