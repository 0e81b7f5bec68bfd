#pragma once
// Small fixed-size vectors for geometry. Plain aggregates, no SIMD.
#include <algorithm>
#include <cmath>

namespace edrnr {

template <class T>
struct Vec3 {
  T x{}, y{}, z{};

  // Component i in [0, 3): a member looked up in a table (one load and an
  // add where i is not known at compile time, not two compares).
  constexpr T& operator[](int i) { return this->*kAxis[i]; }
  constexpr const T& operator[](int i) const { return this->*kAxis[i]; }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator*(const Vec3& o) const { return {x * o.x, y * o.y, z * o.z}; }
  constexpr Vec3 operator/(const Vec3& o) const { return {x / o.x, y / o.y, z / o.z}; }
  constexpr Vec3 operator*(T s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(T s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  constexpr bool operator==(const Vec3& o) const = default;

  template <class U>
  constexpr Vec3<U> cast() const {
    return {U(x), U(y), U(z)};
  }

 private:
  static constexpr T Vec3::*kAxis[3] = {&Vec3::x, &Vec3::y, &Vec3::z};
};

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;
using Vec3i = Vec3<int>;

template <class T>
constexpr T dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class T>
constexpr Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T>
T length(const Vec3<T>& a) {
  return std::sqrt(dot(a, a));
}
template <class T>
Vec3<T> normalize(const Vec3<T>& a) {
  return a / length(a);
}
template <class T>
constexpr Vec3<T> vmin(const Vec3<T>& a, const Vec3<T>& b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
template <class T>
constexpr Vec3<T> vmax(const Vec3<T>& a, const Vec3<T>& b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}

// Axis-aligned box [lo, hi].
template <class T>
struct Box3 {
  Vec3<T> lo, hi;
  constexpr Vec3<T> size() const { return hi - lo; }
  constexpr bool contains(const Vec3<T>& p) const {
    return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
  }
  constexpr bool operator==(const Box3& o) const = default;
};
using Box3f = Box3<float>;
using Box3d = Box3<double>;

// Slab test of the ray o + t*d against box b. On a hit, [t_near, t_far] is the
// parametric interval inside the box (t_near may be negative when o is inside).
template <class T>
bool intersect_box(const Vec3<T>& o, const Vec3<T>& d, const Box3<T>& b, T& t_near, T& t_far) {
  T tn = -INFINITY, tf = INFINITY;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == T(0)) {
      if (o[a] < b.lo[a] || o[a] > b.hi[a]) return false;
      continue;
    }
    T inv = T(1) / d[a];
    T t0 = (b.lo[a] - o[a]) * inv, t1 = (b.hi[a] - o[a]) * inv;
    if (t0 > t1) std::swap(t0, t1);
    tn = std::max(tn, t0);
    tf = std::min(tf, t1);
  }
  t_near = tn;
  t_far = tf;
  return tn <= tf;
}

}  // namespace edrnr
