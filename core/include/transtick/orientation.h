// A volume's place in world space: its index axes' directions and origin, as
// the readers set them from a file's header, and how they are described.
//
// World space is patient space in LPS (+x toward the patient's left, +y
// posterior, +z superior), as DICOM, ITK and MetaImage have it; readers of
// RAS formats (NIfTI, NRRD with a RAS space) convert. Cameras are given in
// world space about the volume's centre; camera.h's ToVolumeFrame maps them
// into the volume's own frame, where the tracer works.
#ifndef TRANSTICK_ORIENTATION_H_
#define TRANSTICK_ORIENTATION_H_

#include <array>
#include <string>

#include "absl/status/status.h"
#include "transtick/volume.h"

namespace transtick {

// Axes whose directions are further from orthogonal than this (the cosine of
// the angle between two of them) are a shear, which a rectilinear grid
// cannot show: SetOrientation refuses them.
inline constexpr double kMaxAxisCosine = 1e-3;

// Sets `volume`'s direction and origin from a header's axes: axes[a] is index
// axis a's step in world space (any positive length; its length is not used)
// and `origin` the world position of sample (0, 0, 0). The directions are
// normalised and made exactly orthonormal (Gram-Schmidt, x first). When they
// form a reflection (determinant -1), the samples are reversed along x, and
// direction[0] and the origin changed to match, so that `direction` is a
// rotation and the world geometry is the file's.
// REQUIRES: volume->dims and values are set.
// Errors (InvalidArgument, naming `path`): an axis that is zero or not
// finite, a non-finite origin, axes not orthogonal within kMaxAxisCosine.
absl::Status SetOrientation(const std::string& path, const std::array<std::array<double, 3>, 3>& axes,
                            const std::array<double, 3>& origin, Volume* volume);

bool IsIdentity(const Direction& direction);

// Each index axis's nearest anatomical direction, as ITK and ParaView name
// orientations: "LPS" for the identity, "RAI" for x toward the right, y
// anterior, z inferior.
std::string OrientationCode(const Direction& direction);

// One line for `transtick info`: the code, the axes and the origin.
std::string DescribeOrientation(const Volume& volume);

}  // namespace transtick

#endif  // TRANSTICK_ORIENTATION_H_
