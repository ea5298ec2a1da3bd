// Translation between transtick's protobuf messages (and their JSON files)
// and the core's types. The one place where both are known.
#ifndef TRANSTICK_API_CONVERT_H_
#define TRANSTICK_API_CONVERT_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "cluster.pb.h"
#include "transtick.pb.h"
#include "transtick/camera.h"
#include "transtick/classification.h"
#include "transtick/tracer.h"

namespace transtick {

// Reads a small text file (at most `max_bytes`); errors name the file.
absl::StatusOr<std::string> ReadTextFile(const std::string& path, size_t max_bytes = 16 << 20);

// Parses protobuf JSON into `message`; unknown fields are errors. `source`
// names the input in messages (a file name).
absl::Status ParseJson(std::string_view json, const std::string& source,
                       google::protobuf::Message* message);

absl::StatusOr<Classification> ToClassification(const v1::MaterialSet& set);
absl::StatusOr<TransferFunction> ToTransferFunction(const v1::TransferFunction& tf);

// Reads and validates a materials (or transfer function) JSON file.
absl::StatusOr<Classification> LoadMaterials(const std::string& path);
absl::StatusOr<TransferFunction> LoadTransferFunction(const std::string& path);

// A view's camera and render settings. ToCameraSpec checks what Camera
// does not: the projection name, vector lengths, finite numbers.
absl::StatusOr<CameraSpec> ToCameraSpec(const v1::View& view);
RenderSettings ToRenderSettings(const v1::View& view);

// Protobuf JSON with the field names as written in the .proto.
std::string ToJson(const google::protobuf::Message& message);

}  // namespace transtick

#endif  // TRANSTICK_API_CONVERT_H_
