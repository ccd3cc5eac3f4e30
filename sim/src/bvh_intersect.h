// Exact ray-primitive intersection and surface normals for the ray caster's traversal
// (raycaster.cpp), inline so that the traversal loop keeps them in place.
#pragma once

#include "bvh.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace segmatch::sim::bvh {

// ---------------------------------------------------------------------------------------
// Exact primitive intersection. Each returns true with *t in [tmin, tmax] and a face code
// used afterwards to compute the normal.

inline bool select_t(float tnear, float tfar, float tmin, float tmax, float* t, bool* exit) {
  if (!(tnear <= tfar)) return false;
  if (tnear >= tmin) {
    if (tnear > tmax) return false;
    *t = tnear;
    *exit = false;
    return true;
  }
  if (tfar >= tmin && tfar <= tmax) {
    *t = tfar;
    *exit = true;
    return true;
  }
  return false;
}

inline bool intersect_box(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t, int* face) {
  const float c = p.f[6], s = p.f[7];
  const float rx = r.o[0] - p.f[0], ry = r.o[1] - p.f[1], rz = r.o[2] - p.f[2];
  // Into the box frame: rotate by -yaw about z.
  const float lox = c * rx + s * ry;
  const float loy = c * ry - s * rx;
  const float ldx = c * r.d[0] + s * r.d[1];
  const float ldy = c * r.d[1] - s * r.d[0];
  const float ilx = safe_inv(ldx), ily = safe_inv(ldy), ilz = r.inv[2];
  const float hx = p.f[3], hy = p.f[4], hz = p.f[5];
  const float tx0 = (-hx - lox) * ilx, tx1 = (hx - lox) * ilx;
  const float ty0 = (-hy - loy) * ily, ty1 = (hy - loy) * ily;
  const float tz0 = (-hz - rz) * ilz, tz1 = (hz - rz) * ilz;
  const float nx = std::min(tx0, tx1), fx = std::max(tx0, tx1);
  const float ny = std::min(ty0, ty1), fy = std::max(ty0, ty1);
  const float nz = std::min(tz0, tz1), fz = std::max(tz0, tz1);
  const float tnear = std::max(nx, std::max(ny, nz));
  const float tfar = std::min(fx, std::min(fy, fz));
  bool exit = false;
  if (!select_t(tnear, tfar, tmin, tmax, t, &exit)) return false;
  if (!exit) {
    *face = (tnear == nx) ? 0 : (tnear == ny ? 1 : 2);
  } else {
    *face = (tfar == fx) ? 0 : (tfar == fy ? 1 : 2);
  }
  return true;
}

// Roots of a*t^2 + 2*b*t + c = 0 with the discriminant given precisely as disc = b^2 - a*c
// (computed by the caller in a cancellation-free form). Returns false if no real root.
inline bool solve_quadratic(float a, float b, float c, float disc, float* t0, float* t1) {
  if (disc < 0.0f) return false;
  const float sq = std::sqrt(disc);
  const float q = -(b + std::copysign(sq, b));
  if (q == 0.0f) {
    *t0 = *t1 = 0.0f;  // b == 0 and disc == 0: tangent at the closest point t = 0
    return true;
  }
  const float ra = q / a, rb = c / q;
  *t0 = std::min(ra, rb);
  *t1 = std::max(ra, rb);
  return true;
}

inline bool intersect_cylinder(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t, int* face) {
  const float px = r.o[0] - p.f[0], py = r.o[1] - p.f[1];
  const float dx = r.d[0], dy = r.d[1];
  const float rr = p.f[5];
  const float a = dx * dx + dy * dy;
  float ts0, ts1;
  if (a > 0.0f) {
    const float b = px * dx + py * dy;
    const float c = px * px + py * py - rr;
    const float cr = px * dy - py * dx;
    if (!solve_quadratic(a, b, c, rr * a - cr * cr, &ts0, &ts1)) return false;
  } else {  // vertical ray: inside the infinite cylinder everywhere or nowhere
    if (px * px + py * py > rr) return false;
    ts0 = -std::numeric_limits<float>::infinity();
    ts1 = std::numeric_limits<float>::infinity();
  }
  const float tz0 = (p.f[2] - r.o[2]) * r.inv[2], tz1 = (p.f[4] - r.o[2]) * r.inv[2];
  const float nz = std::min(tz0, tz1), fz = std::max(tz0, tz1);
  const float tnear = std::max(ts0, nz), tfar = std::min(ts1, fz);
  bool exit = false;
  if (!select_t(tnear, tfar, tmin, tmax, t, &exit)) return false;
  if (!exit) {
    *face = (tnear == ts0) ? 0 : 1;  // 0 = side, 1 = cap
  } else {
    *face = (tfar == ts1) ? 0 : 1;
  }
  return true;
}

inline bool intersect_ellipsoid(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t) {
  const float sx = p.f[3], sy = p.f[4], sz = p.f[5];
  // Scale into the unit-sphere frame (the ray parameter t is unchanged).
  const float ox = (r.o[0] - p.f[0]) * sx, oy = (r.o[1] - p.f[1]) * sy, oz = (r.o[2] - p.f[2]) * sz;
  const float dx = r.d[0] * sx, dy = r.d[1] * sy, dz = r.d[2] * sz;
  const float a = dx * dx + dy * dy + dz * dz;
  const float b = ox * dx + oy * dy + oz * dz;
  const float c = ox * ox + oy * oy + oz * oz - 1.0f;
  const float cx = oy * dz - oz * dy, cy = oz * dx - ox * dz, cz = ox * dy - oy * dx;
  const float disc = a - (cx * cx + cy * cy + cz * cz);  // == b^2 - a*c, without cancellation
  float t0, t1;
  if (!solve_quadratic(a, b, c, disc, &t0, &t1)) return false;
  bool exit = false;
  return select_t(t0, t1, tmin, tmax, t, &exit);
}

inline bool intersect_triangle(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t) {
  // Moller-Trumbore, two-sided.
  const float e1x = p.f[3], e1y = p.f[4], e1z = p.f[5];
  const float e2x = p.f[6], e2y = p.f[7], e2z = p.f[8];
  const float px = r.d[1] * e2z - r.d[2] * e2y;
  const float py = r.d[2] * e2x - r.d[0] * e2z;
  const float pz = r.d[0] * e2y - r.d[1] * e2x;
  const float det = e1x * px + e1y * py + e1z * pz;
  if (det == 0.0f) return false;
  // Reject on the unnormalised barycentrics first (no division on the common miss path).
  const float adet = std::fabs(det);
  const float sgn = det > 0.0f ? 1.0f : -1.0f;
  const float lo = -kBaryEps * adet, hi = (1.0f + kBaryEps) * adet;
  const float sx = r.o[0] - p.f[0], sy = r.o[1] - p.f[1], sz = r.o[2] - p.f[2];
  const float u = (sx * px + sy * py + sz * pz) * sgn;
  if (!(u >= lo && u <= hi)) return false;
  const float qx = sy * e1z - sz * e1y;
  const float qy = sz * e1x - sx * e1z;
  const float qz = sx * e1y - sy * e1x;
  const float v = (r.d[0] * qx + r.d[1] * qy + r.d[2] * qz) * sgn;
  if (!(v >= lo && u + v <= hi)) return false;
  const float tt = (e2x * qx + e2y * qy + e2z * qz) / det;
  if (!(tt >= tmin && tt <= tmax)) return false;
  *t = tt;
  return true;
}

inline bool intersect(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t, int* face) {
  switch (static_cast<Shape>(p.shape)) {
    case Shape::kTriangle: return intersect_triangle(p, r, tmin, tmax, t);
    case Shape::kBox: return intersect_box(p, r, tmin, tmax, t, face);
    case Shape::kCylinder: return intersect_cylinder(p, r, tmin, tmax, t, face);
    case Shape::kEllipsoid: return intersect_ellipsoid(p, r, tmin, tmax, t);
  }
  return false;
}

inline Eigen::Vector3f surface_normal(const PackedPrim& p, const Ray& r, float t, int face) {
  Eigen::Vector3f n = Eigen::Vector3f::UnitZ();
  switch (static_cast<Shape>(p.shape)) {
    case Shape::kBox:
      if (face == 0) {
        n = Eigen::Vector3f(p.f[6], p.f[7], 0.0f);
      } else if (face == 1) {
        n = Eigen::Vector3f(-p.f[7], p.f[6], 0.0f);
      }
      break;
    case Shape::kCylinder:
      if (face == 0) {
        n = Eigen::Vector3f(r.o[0] + t * r.d[0] - p.f[0], r.o[1] + t * r.d[1] - p.f[1], 0.0f);
      }
      break;
    case Shape::kEllipsoid: {
      // Gradient of |S^-1 (x - c)|^2 is S^-2 (x - c) = S^-1 * (unit-sphere point).
      const float sx = p.f[3], sy = p.f[4], sz = p.f[5];
      const float ux = (r.o[0] - p.f[0]) * sx + t * r.d[0] * sx;
      const float uy = (r.o[1] - p.f[1]) * sy + t * r.d[1] * sy;
      const float uz = (r.o[2] - p.f[2]) * sz + t * r.d[2] * sz;
      n = Eigen::Vector3f(ux * sx, uy * sy, uz * sz);
      break;
    }
    case Shape::kTriangle:
      n = Eigen::Vector3f(p.f[3], p.f[4], p.f[5]).cross(Eigen::Vector3f(p.f[6], p.f[7], p.f[8]));
      break;
  }
  const float len = n.norm();
  if (!(len > 0.0f) || !std::isfinite(len)) {
    n = -Eigen::Vector3f(r.d[0], r.d[1], r.d[2]);  // degenerate: face the ray head-on
  } else {
    n /= len;
  }
  if (n.x() * r.d[0] + n.y() * r.d[1] + n.z() * r.d[2] > 0.0f) n = -n;
  return n;
}

}  // namespace segmatch::sim::bvh
