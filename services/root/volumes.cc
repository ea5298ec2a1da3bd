#include "volumes.h"

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
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

// `text` as a reply may carry it: unchanged when Listable, else with
// every byte outside printable ASCII shown as '?'.
std::string ListableText(std::string text) {
  if (Listable(text)) return text;
  for (char& c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u >= 0x7f) c = '?';
  }
  return text;
}

// The entries of a DICOM directory `path`: one per series it holds as
// `found` describes them, or the directory alone (unread, or unreadable).
void AddDicomDirectory(const std::string& path, uint64_t bytes,
                       const DicomSeriesCache::Found* found, std::vector<v1::VolumeEntry>* out) {
  v1::VolumeEntry dir_entry;
  dir_entry.set_path(path);
  dir_entry.set_series(true);
  dir_entry.set_bytes(bytes);
  if (found == nullptr) {
    out->push_back(std::move(dir_entry));
    return;
  }
  if (!found->ok()) {
    dir_entry.set_error(ListableText(std::string(found->status().message())));
    out->push_back(std::move(dir_entry));
    return;
  }
  for (const DicomSeriesInfo& info : **found) {
    v1::VolumeEntry v = dir_entry;
    v.set_bytes(info.bytes);
    v.set_description(ListableText(
        absl::StrCat(info.summary, ", ", info.columns, "x", info.rows, "x", info.frames)));
    if (info.path.empty()) {
      // Opening the directory gives the error that lists the series.
      v.set_error(ListableText(absl::StrCat("series '", info.uid,
                                            "': its SeriesInstanceUID is not digits and dots, so "
                                            "no path can name it")));
    } else {
      v.set_path(info.path);
      v.set_error(ListableText(info.problem));
    }
    out->push_back(std::move(v));
  }
}

}  // namespace

std::optional<DicomSeriesCache::Found> DicomSeriesCache::Get(const std::string& relative,
                                                             uint64_t fingerprint) {
  absl::MutexLock lock(&mu_);
  for (auto it = entries_.begin(); it != entries_.end(); ++it) {
    if (it->relative != relative) continue;
    if (it->fingerprint != fingerprint) return std::nullopt;
    entries_.splice(entries_.begin(), entries_, it);
    return entries_.front().found;
  }
  return std::nullopt;
}

void DicomSeriesCache::Put(const std::string& relative, uint64_t fingerprint, Found found) {
  absl::MutexLock lock(&mu_);
  entries_.remove_if([&](const Entry& e) { return e.relative == relative; });
  entries_.push_front({relative, fingerprint, std::move(found)});
  while (entries_.size() > capacity_) entries_.pop_back();
}

absl::StatusOr<v1::VolumesReply> ListVolumes(const ConfinedDir& dir,
                                             const VolumeListingBounds& bounds,
                                             DicomSeriesCache* cache) {
  // Every file a DICOM directory's headers are read from is opened beneath
  // the data directory, as a job's volume is.
  ReadOptions confined;
  confined.open = [&dir](const std::string& path) { return dir.OpenFile(path); };
  confined.list = [&dir](const std::string& path) { return dir.ListDir(path); };
  size_t headers_left = bounds.dicom_headers;
  DicomReadBudget header_bytes{bounds.dicom_bytes};
  v1::VolumesReply reply;
  std::vector<v1::VolumeEntry> found;
  size_t examined = 0;
  bool truncated = false;  // the walk stopped at a bound
  bool unread = false;     // a DICOM directory's headers were past theirs
  std::deque<std::pair<std::string, int>> pending = {{".", 0}};  // directory, depth
  while (!pending.empty() && !truncated) {
    auto [path, depth] = pending.front();
    pending.pop_front();
    auto names = dir.ListDir(path);
    if (!names.ok()) continue;  // vanished, or unreadable: not listed
    std::sort(names->begin(), names->end());
    uint64_t dicom_bytes = 0;  // the files not listed as volumes of their own
    bool dicom = false;
    int probed = 0;
    // The directory's files as the cache tells them apart: names, sizes,
    // modification times.
    std::string files_seen;
    size_t files = 0;
    for (const std::string& name : *names) {
      if (name.empty() || name.front() == '.') continue;
      if (++examined > bounds.examined) {
        truncated = true;
        break;
      }
      const std::string child = Join(path, name);
      auto entry = dir.Stat(child);
      if (!entry.ok()) continue;
      if (entry->regular) {
        // Every file a DICOM directory's reader reads, those whose names
        // are not listed included, counts among what the cache tells apart.
        ++files;
        absl::StrAppend(&files_seen, name, "/", entry->bytes, "/", entry->mtime_ns, "\n");
      }
      if (!Listable(name)) continue;
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
      // A directory the walk left part-way is not read.
      const uint64_t fingerprint = std::hash<std::string>{}(files_seen) ^ files;
      std::optional<DicomSeriesCache::Found> series;
      if (cache && !truncated) series = cache->Get(path, fingerprint);
      if (!series && !truncated && files <= headers_left && !header_bytes.exhausted) {
        headers_left -= files;
        series = ListDicomSeries(path, confined, &header_bytes);
        if (header_bytes.exhausted) {
          series.reset();  // read in part: listed as unread, and not kept
        } else if (cache) {
          cache->Put(path, fingerprint, *series);
        }
      }
      if (!series) unread = true;  // its headers are past the bound
      AddDicomDirectory(path, dicom_bytes, series ? &*series : nullptr, &found);
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
  reply.set_truncated(truncated || unread);
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
