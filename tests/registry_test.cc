// The root's registry: registration, renewal by heartbeat, expiry, and what
// a worker is believed to hold.
#include "registry.h"

#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"

namespace transtick {
namespace {

v1::RegisterRequest Request(const std::string& id, const std::string& address) {
  v1::RegisterRequest r;
  r.set_id(id);
  r.set_address(address);
  r.set_threads(2);
  return r;
}

TEST(RegistryTest, HeartbeatsKeepAWorkerAndSilenceDropsIt) {
  Registry registry(std::chrono::milliseconds(300));
  ASSERT_TRUE(registry.Register(Request("a", "127.0.0.1:1")).ok());
  ASSERT_TRUE(registry.Register(Request("b", "127.0.0.1:2")).ok());
  registry.SetHeld("a", HeldSlab{"k@0-10", "k", 0, 10, 0});
  // "a" renews every 100 ms; "b" says nothing.
  for (int i = 0; i < 6; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    absl::Status s = registry.Register(Request("a", "127.0.0.1:1"));
    EXPECT_EQ(s.code(), absl::StatusCode::kAlreadyExists) << s;
  }
  EXPECT_TRUE(registry.Alive("a"));
  EXPECT_FALSE(registry.Alive("b"));
  EXPECT_EQ(registry.size(), 1);
  EXPECT_EQ(registry.Held().count("a"), 1u);
  // The same id from another address is refused and renews nothing: "a"
  // expires on time although the impostor keeps calling.
  const auto last_renewal = std::chrono::steady_clock::now();
  while (true) {
    absl::Status s = registry.Register(Request("a", "127.0.0.1:9"));
    // OK only once "a" at :1 has expired: then the caller is a new worker.
    if (s.ok() || !registry.Alive("a")) break;
    EXPECT_EQ(s.code(), absl::StatusCode::kAlreadyExists) << s;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_LT(std::chrono::steady_clock::now() - last_renewal, std::chrono::seconds(5));
  }
  EXPECT_GE(std::chrono::steady_clock::now() - last_renewal, std::chrono::milliseconds(290));
  EXPECT_EQ(registry.Held().count("a"), 0u);  // forgotten with its slab
  (void)registry.Unregister("a");
  // Once dropped, a worker registers anew (a root that forgot it, or a
  // worker that came back).
  EXPECT_TRUE(registry.Register(Request("a", "127.0.0.1:1")).ok());
  EXPECT_TRUE(registry.Alive("a"));
}

TEST(RegistryTest, WhereAWorkerRunsIsCheckedAndKept) {
  Registry registry(std::chrono::milliseconds(5000));
  // Hostile claims are refused by name, and register nothing.
  struct Bad {
    double cpus;
    int machine_cpus;
    std::string machine;
    const char* says;
  };
  const Bad bad[] = {{-1, 2, "m", "CPU count"},       {std::nan(""), 2, "m", "CPU count"},
                     {1e300, 2, "m", "CPU count"},    {1, -4, "m", "CPU count"},
                     {1, 1 << 30, "m", "CPU count"},  {1, 2, std::string(65, 'a'), "machine id"},
                     {1, 2, "boot id", "machine id"}, {1, 2, std::string("m\0x", 3), "machine id"}};
  for (const Bad& b : bad) {
    v1::RegisterRequest r = Request("w", "127.0.0.1:5");
    r.set_cpus(b.cpus);
    r.set_machine_cpus(b.machine_cpus);
    r.set_machine(b.machine);
    const absl::Status s = registry.Register(r);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
    EXPECT_NE(s.message().find(b.says), std::string::npos) << s;
    EXPECT_EQ(registry.size(), 0);
  }
  v1::RegisterRequest r = Request("w", "127.0.0.1:5");
  r.set_cpus(1.5);
  r.set_machine_cpus(8);
  r.set_machine("0b9e0c7a-6c1f-4a55-9d7e-2f1c3b5a7d90");
  ASSERT_TRUE(registry.Register(r).ok());
  v1::StatusReply status;
  registry.Describe(&status);
  ASSERT_EQ(status.workers_size(), 1);
  EXPECT_EQ(status.workers(0).cpus(), 1.5);
  EXPECT_EQ(status.workers(0).machine_cpus(), 8);
  EXPECT_EQ(status.workers(0).machine(), r.machine());
}

// Whether the workers share one machine (the root's, for its frames'
// overlap: RunnerOptions::frames_tracing auto).
TEST(RegistryTest, AllOnSaysWhetherEveryWorkerRunsOnOneMachine) {
  const std::string here = "0b9e0c7a-6c1f-4a55-9d7e-2f1c3b5a7d90";
  const std::string there = "7d1e3c2b-0000-4a55-9d7e-2f1c3b5a7d91";
  Registry registry(std::chrono::milliseconds(5000));
  EXPECT_TRUE(registry.AllOn(here));  // no worker: none elsewhere
  v1::RegisterRequest a = Request("a", "127.0.0.1:1");
  a.set_machine(here);
  ASSERT_TRUE(registry.Register(a).ok());
  EXPECT_TRUE(registry.AllOn(here));
  EXPECT_FALSE(registry.AllOn(there));
  EXPECT_FALSE(registry.AllOn(""));  // the root's own machine unknown
  v1::RegisterRequest b = Request("b", "127.0.0.1:2");
  b.set_machine(here);
  ASSERT_TRUE(registry.Register(b).ok());
  EXPECT_TRUE(registry.AllOn(here));
  v1::RegisterRequest c = Request("c", "10.0.0.3:1");
  c.set_machine(there);
  ASSERT_TRUE(registry.Register(c).ok());
  EXPECT_FALSE(registry.AllOn(here));
  v1::RegisterRequest d = Request("d", "10.0.0.4:1");  // says nothing of its machine
  Registry unknown(std::chrono::milliseconds(5000));
  ASSERT_TRUE(unknown.Register(a).ok());
  ASSERT_TRUE(unknown.Register(d).ok());
  EXPECT_FALSE(unknown.AllOn(here));
}

TEST(RegistryTest, WorkersWaitsForAFirstWorkerAndHonoursCancel) {
  Registry registry;
  auto none = registry.Workers(std::chrono::milliseconds(50), [] { return false; });
  EXPECT_EQ(none.status().code(), absl::StatusCode::kUnavailable);
  auto cancelled = registry.Workers(std::chrono::seconds(5), [] { return true; });
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
  std::thread late([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ASSERT_TRUE(registry.Register(Request("w", "127.0.0.1:3")).ok());
  });
  auto got = registry.Workers(std::chrono::seconds(5), [] { return false; });
  late.join();
  ASSERT_TRUE(got.ok()) << got.status();
  ASSERT_EQ(got->size(), 1u);
  EXPECT_EQ((*got)[0]->id, "w");
  EXPECT_FALSE(registry.Register(Request("", "x")).ok());
}

// A call that could not reach a worker drops it only when a new connection
// fails too: a worker that is gone goes, one that takes the connection
// (its first attempt met a passing failure) keeps its place.
TEST(RegistryTest, AFailedConnectDropsOnlyAWorkerThatRefusesANewOne) {
  // A loopback port with nothing on it: a server's, stopped.
  int port = 0;
  v1::Worker::CallbackService unimplemented;  // a server needs a service
  {
    grpc::ServerBuilder b;
    b.RegisterService(&unimplemented);
    b.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    auto server = b.BuildAndStart();
    ASSERT_NE(server, nullptr);
    server->Shutdown();
  }
  ASSERT_GT(port, 0);
  const std::string address = absl::StrCat("127.0.0.1:", port);
  Registry registry(std::chrono::seconds(60));
  ASSERT_TRUE(registry.Register(Request("gone", address)).ok());
  const auto t0 = std::chrono::steady_clock::now();
  registry.Drop("gone", "failed to connect", std::chrono::milliseconds(300));
  EXPECT_FALSE(registry.Alive("gone"));
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(299));

  ASSERT_TRUE(registry.Register(Request("back", address)).ok());
  auto workers = registry.Workers(std::chrono::milliseconds(0), [] { return false; });
  ASSERT_TRUE(workers.ok()) << workers.status();
  ASSERT_EQ(workers->size(), 1u);
  // Its first connection fails, as a call's would ...
  const auto& channel = (*workers)[0]->channel;
  EXPECT_FALSE(channel->WaitForConnected(std::chrono::system_clock::now() +
                                         std::chrono::milliseconds(200)));
  EXPECT_NE(channel->GetState(false), GRPC_CHANNEL_READY);
  // ... and by the time the root drops it, the worker listens.
  grpc::ServerBuilder b;
  b.RegisterService(&unimplemented);
  int again = 0;
  b.AddListeningPort(address, grpc::InsecureServerCredentials(), &again);
  auto server = b.BuildAndStart();
  ASSERT_NE(server, nullptr);
  ASSERT_EQ(again, port);
  registry.Drop("back", "failed to connect", std::chrono::seconds(10));
  EXPECT_TRUE(registry.Alive("back"));
  EXPECT_EQ(channel->GetState(false), GRPC_CHANNEL_READY);
  // Reached and silent (a paused worker) is not given that chance: with
  // the channel connected, the drop is at once.
  registry.Drop("back", "deadline exceeded", std::chrono::seconds(10));
  EXPECT_FALSE(registry.Alive("back"));
  server->Shutdown();
}

}  // namespace
}  // namespace transtick
