#include "slabs.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <map>

#include "absl/strings/str_cat.h"
#include "clock.h"
#include "convert.h"
#include "daemon.h"
#include "fanout.h"
#include "slab_scalars.h"
#include "transtick/partition.h"

namespace transtick {
namespace {

}  // namespace

std::string Layout::SlabKey(const std::string& data_key, const Ring& ring, size_t i) const {
  return absl::StrCat(data_key, "@", ring.cuts[i], "-", ring.cuts[i + 1]);
}

std::vector<size_t> Layout::RingSizes() const {
  std::vector<size_t> sizes;
  for (const Ring& ring : rings) sizes.push_back(ring.workers.size());
  return sizes;
}

Layout Slabs::FormRings(const std::vector<std::shared_ptr<WorkerEntry>>& workers, int rings,
                        int planes) {
  const int n = static_cast<int>(workers.size());
  rings = std::max(1, std::min(rings, n));
  Layout layout;
  for (int r = 0; r < rings; ++r) {
    Layout::Ring ring;
    const int begin = r * n / rings, end = (r + 1) * n / rings;
    // A slab holds at least one plane: extra workers stay idle.
    const int k = std::min(end - begin, planes);
    for (int i = 0; i < k; ++i) ring.workers.push_back(workers[begin + i]);
    ring.cuts = UniformCuts(planes, k);
    layout.rings.push_back(std::move(ring));
  }
  return layout;
}

std::string Layout::Members() const {
  std::string m;
  for (const Ring& ring : rings) {
    for (const auto& w : ring.workers) absl::StrAppend(&m, w->id, ",");
    m += ";";
  }
  return m;
}

std::vector<std::vector<int>> Layout::Cuts() const {
  std::vector<std::vector<int>> cuts;
  for (const Ring& ring : rings) cuts.push_back(ring.cuts);
  return cuts;
}

bool Layout::SetCuts(const std::vector<std::vector<int>>& cuts, int planes) {
  if (cuts.size() != rings.size()) return false;
  for (size_t r = 0; r < rings.size(); ++r) {
    if (!ValidCuts(cuts[r], planes, static_cast<int>(rings[r].workers.size()))) return false;
  }
  for (size_t r = 0; r < rings.size(); ++r) rings[r].cuts = cuts[r];
  return true;
}

absl::Status Slabs::LoadSlab(const LoadedDataset& data, WorkerEntry& worker, const std::string& key,
                             int y0, int y1) {
  const Scene& scene = data.scene;
  const auto& dims = scene.dims();
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(300));
  v1::LoadReply reply;
  auto writer = worker.stub->LoadSlab(&ctx, &reply);
  v1::SlabChunk chunk;
  v1::SlabHeader* h = chunk.mutable_header();
  h->set_dataset_key(key);
  h->set_mode(ToProto(data.mode));
  for (int a = 0; a < 3; ++a) h->add_dims(dims[a]);
  for (int a = 0; a < 3; ++a) h->add_spacing(scene.spacing()[a]);
  h->add_value_range(scene.value_range()[0]);
  h->add_value_range(scene.value_range()[1]);
  if (data.spec.has_materials()) *h->mutable_materials() = data.spec.materials();
  if (data.spec.has_transfer()) *h->mutable_transfer() = data.spec.transfer();
  h->set_y_begin(y0);
  h->set_y_end(y1);
  const auto& bricks = scene.bricks().bytes();
  h->set_brick_map(std::string(bricks.begin(), bricks.end()));
  const auto& summary = scene.summary().bytes();
  h->set_field_summary(std::string(summary.begin(), summary.end()));
  const int sb = scene.ScalarBegin(y0), se = scene.ScalarEnd(y1);
  h->set_scalar_count(static_cast<uint64_t>(dims[0]) * (se - sb) * dims[2]);
  constexpr size_t kChunkBytes = 1 << 20;
  size_t pending = 0;
  auto send = [&]() -> bool {
    bool ok = writer->Write(chunk);
    chunk.Clear();
    pending = 0;
    return ok;
  };
  bool ok = true;
  for (std::string& block : scene.sticks().EncodeRows(y0, y1)) {
    if (!ok) break;
    pending += block.size();
    chunk.add_blocks(std::move(block));
    if (pending >= kChunkBytes) ok = send();
  }
  // Each z's rows of the slab, in the narrowest coding that gives them back
  // (docs/formats.md, "Slab scalars").
  const size_t row = static_cast<size_t>(dims[0]) * (se - sb);
  for (int z = 0; ok && z < dims[2]; ++z) {
    const float* plane = scene.scalars().data() + (static_cast<size_t>(z) * dims[1] + sb) * dims[0];
    ok = AppendSlabScalars(plane, row, chunk, pending, kChunkBytes, send);
  }
  if (ok && (pending > 0 || chunk.has_header())) ok = send();
  writer->WritesDone();
  grpc::Status s = writer->Finish();
  if (!s.ok()) {
    if (IsWorkerFailure(s)) registry_.Drop(worker.id, s.error_message());
    return absl::Status(FromGrpc(s).code(), absl::StrCat("loading slab [", y0, ", ", y1, ") on ",
                                                         worker.address, ": ", s.error_message()));
  }
  return absl::OkStatus();
}

absl::Status Slabs::Distribute(const LoadedDataset& data, Layout& layout) {
  // What must change: each worker of the layout holds its slab under the
  // slab's key. A worker that holds another slab of the same dataset
  // re-slabs, taking the planes it lacks from the workers that hold them
  // (its neighbours, when cuts move a little); any other is sent its slab.
  struct Move {
    std::shared_ptr<WorkerEntry> worker;
    int ring, y0, y1;
    std::string key;
    HeldSlab old;  // empty key: holds nothing of this dataset
    bool ok = false;
    bool reslabbed = false;
  };
  std::vector<Move> moves;
  const std::map<std::string, HeldSlab> held = registry_.Held();  // by worker id
  for (size_t r = 0; r < layout.rings.size(); ++r) {
    const auto& ring = layout.rings[r];
    for (size_t i = 0; i < ring.workers.size(); ++i) {
      std::string key = layout.SlabKey(data.key, ring, i);
      auto it = held.find(ring.workers[i]->id);
      HeldSlab old = it == held.end() ? HeldSlab{} : it->second;
      if (old.key == key) continue;
      moves.push_back(
          {ring.workers[i], static_cast<int>(r), ring.cuts[i], ring.cuts[i + 1], key, old});
    }
  }
  if (moves.empty()) return absl::OkStatus();
  // Sources of planes: slabs of this dataset held now by workers of the
  // layout (others may be gone), the mover's own ring first (its
  // neighbours hold the planes a moved cut hands over).
  std::map<std::string, std::string> address_of;  // by worker id
  for (const auto& ring : layout.rings)
    for (const auto& w : ring.workers) address_of[w->id] = w->address;
  auto add_sources = [&](const Move& m, v1::ReslabRequest* req) {
    for (bool same_ring : {true, false}) {
      for (const auto& [id, h] : held) {
        auto address = address_of.find(id);
        if (id == m.worker->id || h.data_key != data.key || address == address_of.end() ||
            (h.ring == m.ring) != same_ring) {
          continue;
        }
        v1::PlaneSource* src = req->add_sources();
        src->set_address(address->second);
        src->set_dataset_key(h.key);
        src->set_y_begin(h.y0);
        src->set_y_end(h.y1);
      }
    }
  };
  const auto t0 = Clock::now();
  absl::Status status = ForEachParallel(moves.size(), [&](size_t mi) -> absl::Status {
    Move& m = moves[mi];
    if (!m.old.key.empty() && m.old.data_key == data.key) {
      grpc::ClientContext ctx;
      ctx.set_deadline(Deadline(300));
      v1::ReslabRequest req;
      req.set_old_key(m.old.key);
      req.set_new_key(m.key);
      req.set_y_begin(m.y0);
      req.set_y_end(m.y1);
      add_sources(m, &req);
      v1::LoadReply reply;
      grpc::Status s = m.worker->stub->Reslab(&ctx, req, &reply);
      if (s.ok()) {
        m.ok = m.reslabbed = true;
        return absl::OkStatus();
      }
      // A source that failed comes back as ABORTED; only the mover's own
      // failure drops it.
      if (IsWorkerFailure(s)) {
        registry_.Drop(m.worker->id, s.error_message());
        return absl::UnavailableError(
            absl::StrCat("re-slabbing on ", m.worker->address, ": ", s.error_message()));
      }
      // A source could not help: the root sends the slab itself.
      spdlog::warn("re-slabbing [{}, {}) on {} failed ({}); sending the slab instead", m.y0, m.y1,
                   m.worker->address, s.error_message());
    }
    absl::Status s = LoadSlab(data, *m.worker, m.key, m.y0, m.y1);
    m.ok = s.ok();
    return s;
  });
  // Old slabs go only now: until every move is done they are sources.
  std::vector<std::pair<std::shared_ptr<WorkerEntry>, std::string>> evictions;
  int reslabbed = 0, planes = 0;
  for (const Move& m : moves) {
    if (!m.old.key.empty()) evictions.push_back({m.worker, m.old.key});
    if (m.ok) {
      registry_.SetHeld(m.worker->id, HeldSlab{m.key, data.key, m.y0, m.y1, m.ring});
    } else {
      registry_.ClearHeld(m.worker->id);
    }
    if (m.reslabbed) {
      ++reslabbed;
      planes += std::max(0, m.old.y0 - m.y0) + std::max(0, m.y1 - m.old.y1);
    }
  }
  (void)ForEachParallel(evictions.size(), [&](size_t i) -> absl::Status {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::DatasetRef ref;
    ref.set_dataset_key(evictions[i].second);
    v1::FrameAck ack;
    evictions[i].first->stub->Evict(&ctx, ref, &ack);
    return absl::OkStatus();
  });
  if (!status.ok()) return status;
  layout.load_ms = MsSince(t0);
  layout.planes_moved = planes;
  spdlog::info("slabs: {} sent by the root, {} re-cut with {} planes from neighbours, in {:.0f} ms",
               moves.size() - reslabbed, reslabbed, planes, layout.load_ms);
  return absl::OkStatus();
}

}  // namespace transtick
