// A client of gRPC server reflection (grpc.reflection.v1alpha, as grpcurl
// speaks it) for the tests: the raw bytes of the answer to list_services.
#ifndef TRANSTICK_TESTS_REFLECTION_CLIENT_H_
#define TRANSTICK_TESTS_REFLECTION_CLIENT_H_

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace transtick::testing {

// Sends one ServerReflectionRequest with list_services (field 7, "") on
// `channel` (with `token` as a bearer token when not empty) and returns
// the response's bytes, in which each service's name appears as text;
// `*status` is the call's status.
inline std::string ReflectedServices(const std::shared_ptr<grpc::Channel>& channel,
                                     const std::string& token, grpc::Status* status) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  if (!token.empty()) ctx.AddMetadata("authorization", "Bearer " + token);
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
                               &cq);
  void* tag = nullptr;
  bool ok = false;
  auto step = [&](intptr_t t) {
    cq.Next(&tag, &ok);
    return ok && reinterpret_cast<intptr_t>(tag) == t;
  };
  call->StartCall(reinterpret_cast<void*>(1));
  std::string response;
  if (step(1)) {
    const std::string request("\x3a\x00", 2);
    grpc::Slice slice(request);
    grpc::ByteBuffer out(&slice, 1);
    call->Write(out, reinterpret_cast<void*>(2));
    if (step(2)) {
      grpc::ByteBuffer in;
      call->Read(&in, reinterpret_cast<void*>(3));
      if (step(3)) {
        std::vector<grpc::Slice> slices;
        (void)in.Dump(&slices);
        for (const auto& s : slices) {
          response.append(reinterpret_cast<const char*>(s.begin()), s.size());
        }
        call->WritesDone(reinterpret_cast<void*>(4));
        step(4);
      }
    }
  }
  call->Finish(status, reinterpret_cast<void*>(5));
  cq.Next(&tag, &ok);
  return response;
}

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_REFLECTION_CLIENT_H_
