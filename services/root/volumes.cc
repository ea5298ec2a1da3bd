#include "volumes.h"

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <deque>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "transtick/presets.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

std::string Join(const std::string& dir, const std::string& name) {
  return dir == "." ? name : dir + "/" + name;
}

// Whether the file `relative` begins as a DICOM Part 10 file does: a
// 128-byte preamble, then "DICM".
bool HasDicomMagic(const ConfinedDir& dir, const std::string& relative) {
  auto fd = dir.OpenFile(relative);
  if (!fd.ok()) return false;
  char head[132];
  const ssize_t n = ::pread(*fd, head, sizeof(head), 0);
  ::close(*fd);
  return n == static_cast<ssize_t>(sizeof(head)) && std::memcmp(head + 128, "DICM", 4) == 0;
}

// Whether `name` can go in a protobuf string and be shown as it is: valid
// UTF-8 (shortest forms, no surrogates) without control characters. Other
// names are not listed: a reply holding one could not be sent.
bool Listable(const std::string& name) {
  const auto* p = reinterpret_cast<const unsigned char*>(name.data());
  const auto* end = p + name.size();
  while (p < end) {
    const unsigned char c = *p;
    if (c < 0x20 || c == 0x7f) return false;
    if (c < 0x80) {
      ++p;
      continue;
    }
    const int n = c >= 0xf0 ? 3 : c >= 0xe0 ? 2 : c >= 0xc2 ? 1 : -1;
    if (n < 0 || c > 0xf4 || end - p <= n) return false;
    uint32_t code = c & (0x3f >> n);
    for (int k = 1; k <= n; ++k) {
      if ((p[k] & 0xc0) != 0x80) return false;
      code = (code << 6) | (p[k] & 0x3f);
    }
    const uint32_t least[] = {0, 0x80, 0x800, 0x10000};
    if (code < least[n] || code > 0x10ffff || (code >= 0xd800 && code <= 0xdfff)) return false;
    p += n + 1;
  }
  return true;
}

}  // namespace

absl::StatusOr<v1::VolumesReply> ListVolumes(const ConfinedDir& dir,
                                             const VolumeListingBounds& bounds) {
  v1::VolumesReply reply;
  std::vector<v1::VolumeEntry> found;
  size_t examined = 0;
  bool truncated = false;
  std::deque<std::pair<std::string, int>> pending = {{".", 0}};  // directory, depth
  while (!pending.empty() && !truncated) {
    auto [path, depth] = pending.front();
    pending.pop_front();
    auto names = dir.ListDir(path);
    if (!names.ok()) continue;  // vanished, or unreadable: not listed
    std::sort(names->begin(), names->end());
    uint64_t dicom_bytes = 0;
    bool dicom = false;
    int probed = 0;
    for (const std::string& name : *names) {
      if (name.empty() || name.front() == '.' || !Listable(name)) continue;
      if (++examined > bounds.examined) {
        truncated = true;
        break;
      }
      const std::string child = Join(path, name);
      auto entry = dir.Stat(child);
      if (!entry.ok()) continue;
      if (entry->directory) {
        if (depth + 1 < bounds.depth) {
          pending.emplace_back(child, depth + 1);
        } else {
          truncated = true;
        }
        continue;
      }
      if (!entry->regular) continue;
      if (IsVolumeFileName(name)) {
        v1::VolumeEntry v;
        v.set_path(child);
        v.set_bytes(entry->bytes);
        found.push_back(std::move(v));
        continue;
      }
      const std::string lower = absl::AsciiStrToLower(name);
      if (absl::EndsWith(lower, ".dcm")) {
        dicom = true;
      } else if (!dicom && probed < 4) {  // files without the extension: look at a few
        ++probed;
        dicom = HasDicomMagic(dir, child);
      }
      dicom_bytes += entry->bytes;
    }
    if (dicom && path != ".") {
      v1::VolumeEntry v;
      v.set_path(path);
      v.set_series(true);
      v.set_bytes(dicom_bytes);
      found.push_back(std::move(v));
    }
  }
  if (!pending.empty()) truncated = true;
  std::sort(found.begin(), found.end(),
            [](const v1::VolumeEntry& a, const v1::VolumeEntry& b) { return a.path() < b.path(); });
  if (found.size() > bounds.listed) {
    found.resize(bounds.listed);
    truncated = true;
  }
  for (v1::VolumeEntry& v : found) *reply.add_volumes() = std::move(v);
  reply.set_truncated(truncated);
  for (const PresetInfo& p : ListPresets()) {
    v1::PresetInfo* out = reply.add_presets();
    out->set_name(p.name);
    out->set_description(p.description);
    out->set_surfaces(p.surfaces);
    out->set_dvr(p.dvr);
    out->set_relative(p.relative);
  }
  return reply;
}

}  // namespace transtick
