// The listing of what a client may open (rpc Volumes): the volumes in the
// data directory and the presets. docs/formats.md, "Volumes listing".
#ifndef TRANSTICK_SERVICES_ROOT_VOLUMES_H_
#define TRANSTICK_SERVICES_ROOT_VOLUMES_H_

#include <cstddef>
#include <cstdint>
#include <list>
#include <optional>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"
#include "confined_dir.h"
#include "transtick/volume_io.h"

namespace transtick {

struct VolumeListingBounds {
  int depth = 4;                 // directory levels beneath the data directory
  size_t examined = 20000;       // names looked at in all
  size_t listed = 2000;          // volumes returned
  // DICOM files whose headers one listing reads, and the bytes it reads of
  // them (each file's bytes up to its pixel data, in prefixes of 16 KiB and
  // more: ListDicomSeries).
  size_t dicom_headers = 5000;
  uint64_t dicom_bytes = uint64_t{512} << 20;
};

// The series of DICOM directories as ListDicomSeries found them, each kept
// while the directory's files stay as they were (names, sizes and
// modification times): a listing reads a directory's headers again only
// when one of them changed. At most `capacity` directories, the least
// recently listed going first. Thread-safe.
class DicomSeriesCache {
 public:
  explicit DicomSeriesCache(size_t capacity = 256) : capacity_(capacity) {}
  using Found = absl::StatusOr<std::vector<DicomSeriesInfo>>;
  // What was found in directory `relative` when its files had `fingerprint`.
  std::optional<Found> Get(const std::string& relative, uint64_t fingerprint)
      ABSL_LOCKS_EXCLUDED(mu_);
  void Put(const std::string& relative, uint64_t fingerprint, Found found) ABSL_LOCKS_EXCLUDED(mu_);

 private:
  struct Entry {
    std::string relative;
    uint64_t fingerprint;
    Found found;
  };
  const size_t capacity_;
  absl::Mutex mu_;
  std::list<Entry> entries_ ABSL_GUARDED_BY(mu_);  // most recently used first
};

// Walks `dir`: files whose names ReadVolume reads (IsVolumeFileName), and
// directories that hold DICOM files (a name ending .dcm, or "DICM" at byte
// 128 of one of their first files). A DICOM directory's headers are read
// (ListDicomSeries, through `dir`): it is listed once per series, as the
// path that reads it (the directory, or "DIR#UID" when it holds several),
// with the series' description and, when it would not read, why. Names
// beginning with '.' are skipped, and links that lead outside are not
// followed. Beyond `bounds` the reply is marked truncated; a DICOM
// directory whose headers the bound leaves unread is listed once, without
// a description. `cache` (may be null) keeps what directories' headers
// said between listings. The presets come from ListPresets.
absl::StatusOr<v1::VolumesReply> ListVolumes(const ConfinedDir& dir,
                                             const VolumeListingBounds& bounds = {},
                                             DicomSeriesCache* cache = nullptr);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_VOLUMES_H_
