// A minimal 3-vector for ray geometry and colours.
#ifndef TRANSTICK_VEC_H_
#define TRANSTICK_VEC_H_

#include <cmath>

namespace transtick {

template <typename T>
struct Vec3T {
  T x = 0, y = 0, z = 0;

  constexpr T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3T operator+(const Vec3T& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3T operator-(const Vec3T& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3T operator-() const { return {-x, -y, -z}; }
  constexpr Vec3T operator*(T s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3T operator*(const Vec3T& o) const { return {x * o.x, y * o.y, z * o.z}; }
  constexpr Vec3T operator/(const Vec3T& o) const { return {x / o.x, y / o.y, z / o.z}; }
  Vec3T& operator+=(const Vec3T& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
};

using Vec3 = Vec3T<double>;
using Vec3f = Vec3T<float>;

template <typename T>
constexpr T Dot(const Vec3T<T>& a, const Vec3T<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <typename T>
constexpr Vec3T<T> Cross(const Vec3T<T>& a, const Vec3T<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T>
T Length(const Vec3T<T>& a) {
  return std::sqrt(Dot(a, a));
}
// Returns `a` unchanged when its length is zero.
template <typename T>
Vec3T<T> Normalize(const Vec3T<T>& a) {
  T len = Length(a);
  return len > 0 ? a * (T(1) / len) : a;
}

}  // namespace transtick

#endif  // TRANSTICK_VEC_H_
