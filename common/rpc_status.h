// The one mapping between absl and gRPC statuses. Code below the services
// returns absl::Status; every service boundary converts with ToGrpc, and
// every client with FromGrpc, so a code and its message cross unchanged.
#ifndef TRANSTICK_COMMON_RPC_STATUS_H_
#define TRANSTICK_COMMON_RPC_STATUS_H_

#include <grpcpp/support/status.h>

#include "absl/status/status.h"

namespace transtick {

// absl and gRPC number their codes alike, so the mapping keeps the code and
// the message.
grpc::Status ToGrpc(const absl::Status& status);
absl::Status FromGrpc(const grpc::Status& status);

}  // namespace transtick

#endif  // TRANSTICK_COMMON_RPC_STATUS_H_
