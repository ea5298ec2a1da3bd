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
#include "transtick/partition.h"
#include "transtick/presets.h"
#include "transtick/render.h"
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

// `dataset` with its preset (Dataset.preset) replaced by the preset's
// materials or transfer function for a volume of value range `range`
// (presets.h); a dataset without a preset comes back unchanged. Errors name
// the preset: an unknown name, or a mode the preset has nothing for.
absl::StatusOr<v1::Dataset> ResolvePreset(const v1::Dataset& dataset,
                                          const std::array<float, 2>& range);

// A view's camera and render settings. ToCameraSpec checks what Camera
// does not: the projection name, vector lengths, finite numbers.
absl::StatusOr<CameraSpec> ToCameraSpec(const v1::View& view);
RenderSettings ToRenderSettings(const v1::View& view);
// Both at once.
absl::StatusOr<FrameRequest> ToFrameRequest(const v1::View& view);
// `view` (in world space) with its camera in the frame of a volume of
// `direction` and extent (camera.h's ToVolumeFrame), as an explicit view:
// what the root sends its workers and the in-process render uses. A volume
// of identity direction gets `view` back unchanged.
absl::StatusOr<v1::View> ToVolumeFrame(const v1::View& view, const Direction& direction,
                                       const Vec3& volume_extent);

// The render mode between its proto and core forms; RENDER_MODE_UNSPECIFIED
// and unknown values are an error naming them.
absl::StatusOr<RenderMode> ToRenderMode(v1::RenderMode mode);
v1::RenderMode ToProto(RenderMode mode);

// A proto enum's value by name as job files and the command's flags spell
// it, "test-rays" or "TEST_RAYS" ("" is the enum's 0, its default). Errors
// name `what` and the values that exist.
absl::StatusOr<int> ParseEnumValue(const google::protobuf::EnumDescriptor& type,
                                   std::string_view name, std::string_view what);
template <typename E>
absl::StatusOr<E> ParseEnum(std::string_view name, std::string_view what) {
  auto v = ParseEnumValue(*google::protobuf::GetEnumDescriptor<E>(), name, what);
  if (!v.ok()) return v.status();
  return static_cast<E>(*v);
}
// A value's name in lower case with hyphens ("test-rays"), for logs and
// messages; its number when the enum has no such value.
std::string EnumValueName(const google::protobuf::EnumDescriptor& type, int value);
template <typename E>
std::string EnumName(E value) {
  return EnumValueName(*google::protobuf::GetEnumDescriptor<E>(), static_cast<int>(value));
}

// The balancing of a view: its own, or else its job's (OFF when neither
// says). Fails on a value this build does not know.
absl::StatusOr<v1::BalanceMode> EffectiveBalance(const v1::Job& job, const v1::View& view);
absl::StatusOr<BalanceRule> ToBalanceRule(v1::BalanceRule rule);

// Image chunks (docs/formats.md, "Image chunks"). The encoding a job or a
// session asked for: DEFAULT is FLOAT32; INVALID_ARGUMENT naming `what` for
// a value this build does not know.
absl::StatusOr<v1::ImageEncoding> ToImageEncoding(v1::ImageEncoding encoding,
                                                  std::string_view what);
// A pixel's bytes in a chunk of `encoding` (12 or 3).
int PixelBytes(v1::ImageEncoding encoding);
// The field holding a chunk's rows in `encoding`: rgb or rgb8.
const std::string& ChunkBytes(const v1::ImageChunk& chunk, v1::ImageEncoding encoding);
std::string* MutableChunkBytes(v1::ImageChunk* chunk, v1::ImageEncoding encoding);
// Whether `chunk` holds its rows in `encoding` and only there, in exactly
// (row_end - row_begin) * width pixels (a negative span or width: no).
bool ChunkBytesFit(const v1::ImageChunk& chunk, v1::ImageEncoding encoding);
// The encoding of a chunk whose rows fit one of them (ChunkBytesFit); an
// error naming what is wrong otherwise.
absl::StatusOr<v1::ImageEncoding> ChunkEncoding(const v1::ImageChunk& chunk);

// Protobuf JSON with the field names as written in the .proto and every
// field present; indented, or on one line without `indent`.
std::string ToJson(const google::protobuf::Message& message, bool indent = true);

}  // namespace transtick

#endif  // TRANSTICK_API_CONVERT_H_
