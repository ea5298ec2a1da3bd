// Slabs on the cluster: forming rings from the registered workers, and
// making every worker of a layout hold its slab, re-cutting slabs workers
// already hold with planes from their neighbours where it can and sending
// the rest from the root. Used by the runner thread only.
#ifndef TRANSTICK_SERVICES_ROOT_SLABS_H_
#define TRANSTICK_SERVICES_ROOT_SLABS_H_

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "datasets.h"
#include "registry.h"

namespace transtick {

// The rings of a frame: their workers and cuts.
struct Layout {
  struct Ring {
    std::vector<std::shared_ptr<WorkerEntry>> workers;
    std::vector<int> cuts;  // workers.size() + 1 bounds along Y
  };
  std::vector<Ring> rings;
  double load_ms = 0;    // slab transfers done for this layout
  int planes_moved = 0;  // planes fetched between workers for it

  std::string SlabKey(const std::string& data_key, const Ring& ring, size_t i) const;
  // The workers' ids, ring by ring: the identity balancing cuts belong to.
  std::string Members() const;
  std::vector<std::vector<int>> Cuts() const;
  std::vector<size_t> RingSizes() const;
  // Takes `cuts` (one list per ring) when they fit the rings; else false.
  bool SetCuts(const std::vector<std::vector<int>>& cuts, int planes);
};

class Slabs {
 public:
  // REQUIRES: `registry` outlives this.
  explicit Slabs(Registry& registry) : registry_(registry) {}

  // `workers` (in registration order) split into at most `rings` rings,
  // each ring's slabs cut uniformly; a slab holds at least one plane, so
  // workers beyond the planes stay idle.
  static Layout FormRings(const std::vector<std::shared_ptr<WorkerEntry>>& workers, int rings,
                          int planes);

  // Makes every worker of `layout` hold its slab; records the time and
  // planes moved in the layout. Fails UNAVAILABLE when a worker failed (it
  // is dropped from the registry).
  absl::Status Distribute(const LoadedDataset& data, Layout& layout);

 private:
  absl::Status LoadSlab(const LoadedDataset& data, WorkerEntry& worker, const std::string& key,
                        int y0, int y1);

  Registry& registry_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_SLABS_H_
