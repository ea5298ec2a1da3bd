#include "fuzz_ring.h"

#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>

#include "transtick/check.h"
#include "transtick/framebuffer.h"
#include "transtick/ray_codec.h"
#include "transtick/traversal.h"

namespace transtick::fuzz {
namespace {

[[noreturn]] void Fail(const char* what, const absl::Status& status) {
  std::fprintf(stderr, "fuzz_ring: %s: %s\n", what, std::string(status.message()).c_str());
  std::abort();
}

// Through the wire form, as a ray goes to a neighbour.
RayDescriptor OverWire(const RayDescriptor& ray, uint32_t pixel_limit) {
  std::string record, wire;
  AppendRay(ray, &record);
  PackRays(record, &wire);
  DecodedRays decoded = DecodePackedRays(wire, pixel_limit);
  if (!decoded.error.ok()) Fail("a ray handed on does not decode", decoded.error);
  TRANSTICK_CHECK_EQ(decoded.rays.size(), size_t{1});
  return decoded.rays.front();
}

// Through the wire form, as a deposit goes to the display: queued as a
// record, packed, decoded; the display adds what the record says, which
// must be this deposit.
Deposit DepositOverWire(const Deposit& deposit, uint32_t pixel_limit) {
  std::string record, wire;
  AppendDeposit(deposit, &record);
  PackDeposits(record, &wire);
  auto decoded = DecodePackedDeposits(wire, pixel_limit);
  if (!decoded.ok()) {
    std::fprintf(stderr, "fuzz_ring: deposit colour (%g, %g, %g)\n", deposit.color[0],
                 deposit.color[1], deposit.color[2]);
    Fail("the display refuses a deposit", decoded.status());
  }
  TRANSTICK_CHECK_EQ(decoded->size(), size_t{1});
  const PixelDeposits& d = decoded->front();
  const bool primary = deposit.kind == RayKind::kPrimary;
  TRANSTICK_CHECK_EQ(d.pixel, deposit.pixel);
  TRANSTICK_CHECK_EQ(d.primaries, primary ? 1u : 0u);
  TRANSTICK_CHECK_EQ(d.shadows, primary ? 0u : 1u);
  TRANSTICK_CHECK_EQ(d.spawned, uint32_t{deposit.spawned});
  for (int c = 0; c < 3; ++c) TRANSTICK_CHECK_EQ(d.sum[c], Framebuffer::ToFixed(deposit.color[c]));
  return deposit;
}

}  // namespace

FuzzRing::FuzzRing(const Scene& whole, const std::vector<int>& cuts, const Camera& camera,
                   const RenderSettings& settings)
    : layout_(cuts, whole.dims(), whole.spacing(), camera),
      width_(camera.width()),
      pixel_limit_(static_cast<uint32_t>(camera.width()) * static_cast<uint32_t>(camera.height())) {
  const int n = layout_.slabs();
  // Every slab first: the tracers hold references into slabs_.
  slabs_.reserve(n);
  for (int i = 0; i < n; ++i) slabs_.push_back(whole.Slab(layout_.y_begin(i), layout_.y_end(i)));
  tracers_.reserve(n);
  for (int i = 0; i < n; ++i) tracers_.emplace_back(slabs_[i], settings, camera);
  // A ray takes at most max_segments() steps over all slabs, spawns at most
  // one shadow ray per step, and is handed on at most once per step plus
  // once per slab it merely passes through.
  const int64_t steps = tracers_[0].max_segments() + 1;
  max_calls_ = steps * steps * (n + 1);
}

void FuzzRing::Run(int slab, const RayDescriptor& ray, Origin origin,
                   std::vector<Deposit>* deposits) {
  struct Pending {
    int slab;
    RayDescriptor ray;
  };
  std::vector<Pending> queue = {{slab, ray}};
  std::vector<RayDescriptor> spawned;
  int64_t calls = 0;
  while (!queue.empty()) {
    auto [at, r] = queue.back();
    queue.pop_back();
    TRANSTICK_CHECK_LE(++calls, max_calls_);
    spawned.clear();
    Deposit deposit;
    TraceCounters counters;
    const Tracer::Outcome outcome = tracers_[at].Trace(r, spawned, deposit, counters);
    TRANSTICK_CHECK_EQ(counters.truncated, uint64_t{0});
    for (const RayDescriptor& s : spawned) queue.push_back({at, s});
    if (outcome == Tracer::Outcome::kFinished) {
      deposits->push_back(DepositOverWire(deposit, pixel_limit_));
      continue;
    }
    const RingLayout::Hop hop = layout_.Route(at, r.cell);
    TRANSTICK_CHECK(hop != RingLayout::Hop::kFinished);
    const int to = RingLayout::Neighbour(at, hop);
    TRANSTICK_CHECK(to >= 0 && to < slabs());
    const RayDescriptor sent = OverWire(r, pixel_limit_);
    if (absl::Status s = tracers_[to].Validate(sent); !s.ok()) {
      if (origin == Origin::kRing) Fail("a neighbour refuses a ray the ring made", s);
      ++refused_;
      continue;
    }
    queue.push_back({to, sent});
  }
}

void FuzzRing::RunPixel(int col, int row, std::vector<Deposit>* out) {
  const uint32_t pixel = static_cast<uint32_t>(row) * static_cast<uint32_t>(width_) + col;
  std::vector<Deposit> deposits;
  int roles = 0;
  for (int i = 0; i < slabs(); ++i) {
    RayDescriptor ray;
    switch (layout_.Primary(i, col, row, 0, 1, tracers_[i], &ray)) {
      case RingLayout::PrimaryRole::kTrace:
        ++roles;
        TRANSTICK_CHECK_EQ(layout_.SlabOf(ray.cell[1]), i);
        TRANSTICK_CHECK_EQ(ray.pixel, pixel);
        if (absl::Status s = tracers_[i].Validate(ray); !s.ok()) {
          Fail("a slab refuses the primary ray it made", s);
        }
        Run(i, ray, Origin::kRing, &deposits);
        break;
      case RingLayout::PrimaryRole::kMiss:
        ++roles;
        TRANSTICK_CHECK_EQ(layout_.MissSlab(col, row), i);
        deposits.push_back(DepositOverWire(tracers_[i].MissDeposit(pixel), pixel_limit_));
        break;
      case RingLayout::PrimaryRole::kNone:
        break;
    }
  }
  TRANSTICK_CHECK_EQ(roles, 1);
  // One primary deposit, and the shadow deposits it reports.
  int primaries = 0, shadows = 0, spawned = 0;
  for (const Deposit& d : deposits) {
    TRANSTICK_CHECK_EQ(d.pixel, pixel);
    if (d.kind == RayKind::kPrimary) {
      ++primaries;
      spawned = d.spawned;
    } else {
      ++shadows;
    }
  }
  TRANSTICK_CHECK_EQ(primaries, 1);
  TRANSTICK_CHECK_EQ(shadows, spawned);
  out->insert(out->end(), deposits.begin(), deposits.end());
}

}  // namespace transtick::fuzz
