// Named classifications and transfer functions for common modalities, as
// ParaView's volume presets are: what the command's --preset, a job's
// `preset` and the web viewer offer. A preset gives the materials of
// surfaces mode, the transfer function of dvr mode, or both.
//
// CT presets are in Hounsfield units (a DICOM series after its rescale, a
// NIfTI with its scl_slope): they suit no other scale. The MR preset and the
// colormaps are relative: their values are fractions of the volume's value
// range, which the caller passes.
#ifndef TRANSTICK_PRESETS_H_
#define TRANSTICK_PRESETS_H_

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/classification.h"

namespace transtick {

struct PresetInfo {
  std::string name;         // "ct-bone"
  std::string description;  // one line, for a menu
  bool surfaces = false;    // has materials for surfaces mode
  bool dvr = false;         // has a transfer function for dvr mode
  bool relative = false;    // values are fractions of the volume's range
};

// Every preset, in a fixed order. The returned list is a copy.
std::vector<PresetInfo> ListPresets();

// Preset `name`'s materials or transfer function for a volume whose values
// span `range` (Volume::Range(); used by relative presets only). Errors:
// NotFound for an unknown name, listing the names; InvalidArgument when the
// preset has nothing for that mode. What is returned has been validated.
absl::StatusOr<Classification> PresetMaterials(std::string_view name,
                                               const std::array<float, 2>& range);
absl::StatusOr<TransferFunction> PresetTransfer(std::string_view name,
                                                const std::array<float, 2>& range);

}  // namespace transtick

#endif  // TRANSTICK_PRESETS_H_
