// The listing of what a client may open (rpc Volumes): the volumes in the
// data directory and the presets. docs/formats.md, "Volumes listing".
#ifndef TRANSTICK_SERVICES_ROOT_VOLUMES_H_
#define TRANSTICK_SERVICES_ROOT_VOLUMES_H_

#include <cstddef>

#include "absl/status/statusor.h"
#include "cluster.pb.h"
#include "confined_dir.h"

namespace transtick {

struct VolumeListingBounds {
  int depth = 4;                 // directory levels beneath the data directory
  size_t examined = 20000;       // names looked at in all
  size_t listed = 2000;          // volumes returned
};

// Walks `dir`: files whose names ReadVolume reads (IsVolumeFileName), and
// directories that hold DICOM files (a name ending .dcm, or "DICM" at byte
// 128 of one of their first files), as series. Names beginning with '.' are
// skipped, and links that lead outside are not followed. Beyond `bounds` the
// reply is marked truncated. The presets come from ListPresets.
absl::StatusOr<v1::VolumesReply> ListVolumes(const ConfinedDir& dir,
                                             const VolumeListingBounds& bounds = {});

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_VOLUMES_H_
