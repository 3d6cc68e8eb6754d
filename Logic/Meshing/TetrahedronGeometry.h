#pragma once
// Small 3-vector arithmetic shared by the meshing sources (the lattice mesher, the boundary
// snapping): points as std::array<double, 3>, LPS mm.
#include <array>
#include <cmath>

namespace brainshift::tetrahedron_geometry {

using Vec = std::array<double, 3>;
inline Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec cross(const Vec& a, const Vec& b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }
inline double dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline double norm(const Vec& a) { return std::sqrt(dot(a, a)); }
/// The signed volume of the tetrahedron p0 p1 p2 p3 (positive when
/// (p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0).
inline double signedVolume(const Vec p[4]) { return dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0]))) / 6.0; }

} // namespace brainshift::tetrahedron_geometry
