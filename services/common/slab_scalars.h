// A slab's scalars in SlabChunk messages, as the root sends them (LoadSlab)
// and a worker sends its planes to another (FetchPlanes): docs/formats.md,
// "Slab scalars".
#ifndef TRANSTICK_SERVICES_COMMON_SLAB_SCALARS_H_
#define TRANSTICK_SERVICES_COMMON_SLAB_SCALARS_H_

#include <algorithm>
#include <cstddef>

#include "absl/status/status.h"
#include "cluster.pb.h"
#include "transtick/scalar_codec.h"

namespace transtick {

// Appends `n` samples to `chunk`: pieces of at most kScalarsPiece, each in
// its narrowest coding. `flush()` sends the chunk, clears it and sets
// `pending` to 0, returning whether the stream took it; it is called before
// a piece whose coding differs from the scalars the chunk holds, and once
// `pending` (bytes in the chunk) reaches `chunk_bytes`. Returns false as soon
// as a flush fails.
template <typename Flush>
bool AppendSlabScalars(const float* values, size_t n, v1::SlabChunk& chunk, size_t& pending,
                       size_t chunk_bytes, Flush&& flush) {
  for (size_t i = 0; i < n; i += kScalarsPiece) {
    const size_t k = std::min(kScalarsPiece, n - i);
    const ScalarsCoding coding = NarrowestCoding(values + i, k);
    if (!chunk.scalars().empty() && chunk.scalars_coding() != static_cast<int>(coding) &&
        !flush()) {
      return false;
    }
    chunk.set_scalars_coding(static_cast<v1::ScalarsCoding>(coding));
    AppendScalars(values + i, k, coding, chunk.mutable_scalars());
    pending += k * ScalarsCodingBytes(coding);
    if (pending >= chunk_bytes && !flush()) return false;
  }
  return true;
}

// Decodes the scalars of `chunk` into out[*filled .. room), moving *filled
// past them; an error naming the fault for scalars that do not decode or
// overrun `room` (more than the header announced).
inline absl::Status TakeSlabScalars(const v1::SlabChunk& chunk, float* out, size_t room,
                                    size_t* filled) {
  if (chunk.scalars().empty()) return absl::OkStatus();
  auto n = DecodeScalars(chunk.scalars(), chunk.scalars_coding(), out + *filled, room - *filled);
  if (!n.ok()) return n.status();
  *filled += *n;
  return absl::OkStatus();
}

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_SLAB_SCALARS_H_
