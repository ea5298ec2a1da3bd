// Reactors for a streaming call refused before it began (a caller without
// the right certificate, a frame that is not here): each finishes with its
// status at once and deletes itself when gRPC is done with it.
#ifndef TRANSTICK_SERVICES_COMMON_REFUSED_H_
#define TRANSTICK_SERVICES_COMMON_REFUSED_H_

#include <grpcpp/support/server_callback.h>

#include <utility>

namespace transtick {

template <class Request, class Response>
class RefusedBidi : public grpc::ServerBidiReactor<Request, Response> {
 public:
  explicit RefusedBidi(grpc::Status status) { this->Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

template <class Request>
class RefusedRead : public grpc::ServerReadReactor<Request> {
 public:
  explicit RefusedRead(grpc::Status status) { this->Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

template <class Response>
class RefusedWrite : public grpc::ServerWriteReactor<Response> {
 public:
  explicit RefusedWrite(grpc::Status status) { this->Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_REFUSED_H_
