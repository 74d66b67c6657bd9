// Surface elements in their plane: planar polygons and their clipping, and the
// basis functions of a triangle or bilinear quadrilateral projected on a plane.
// Shared by surface.cpp (surface-surface) and trace.cpp (volume-surface).
#pragma once

#include <algorithm>
#include <cmath>

#include "basis.hpp"
#include "common.hpp"

namespace vc {
namespace {

// ---------------------------------------------------------------------------
// Planar polygons in the auxiliary plane.

struct P2 {
  double x, y;
};

inline double cross2(const P2& a, const P2& b) { return a.x * b.y - a.y * b.x; }
inline P2 sub2(const P2& a, const P2& b) { return {a.x - b.x, a.y - b.y}; }

// Clipping a polygon of <= 4 vertices by a convex one of <= 4 edges gives at
// most 8 vertices when the subject is convex; the headroom covers (rare)
// non-convex projected source quads.
constexpr int kMaxPoly = 32;

struct Poly {
  P2 p[kMaxPoly];
  int n = 0;
  void push(const P2& q) {
    if (n < kMaxPoly) p[n++] = q;
  }
};

// Twice the signed area (shoelace), positive for counter-clockwise polygons.
inline double twice_area(const Poly& P) {
  double s = 0.0;
  for (int i = 0, j = P.n - 1; i < P.n; j = i++) s += cross2(P.p[j], P.p[i]);
  return s;
}

inline void reverse(Poly& P) { std::reverse(P.p, P.p + P.n); }

// Drop consecutive (cyclically) vertices closer than eps (max norm): they come
// from a subject vertex lying on a clip edge, i.e. shared vertices or edges.
inline void remove_duplicates(Poly& P, double eps) {
  if (P.n == 0) return;
  int m = 1;
  for (int i = 1; i < P.n; ++i) {
    const P2& q = P.p[m - 1];
    if (std::fabs(P.p[i].x - q.x) > eps || std::fabs(P.p[i].y - q.y) > eps) P.p[m++] = P.p[i];
  }
  while (m > 1 && std::fabs(P.p[m - 1].x - P.p[0].x) <= eps && std::fabs(P.p[m - 1].y - P.p[0].y) <= eps) --m;
  P.n = m;
}

// Sutherland-Hodgman: clip `P` (counter-clockwise) in place by the convex,
// counter-clockwise polygon `C`. A point is inside the half-plane left of the
// edge (a, b) when its signed distance to the edge line is >= -eps, so points
// on the edge (shared vertices and edges) are kept once and never produce a
// division by zero; the intersection parameter is clamped to [0, 1].
inline void clip_convex(Poly& P, const Poly& C, double eps) {
  Poly out;
  double d[kMaxPoly];
  for (int e = 0; e < C.n && P.n >= 3; ++e) {
    const P2 a = C.p[e], b = C.p[(e + 1) % C.n];
    const P2 ab = sub2(b, a);
    const double len = std::sqrt(ab.x * ab.x + ab.y * ab.y);
    if (len <= eps) continue;  // collapsed edge of the clip polygon
    bool all_in = true;
    for (int i = 0; i < P.n; ++i) {
      d[i] = cross2(ab, sub2(P.p[i], a)) / len;
      all_in = all_in && d[i] >= -eps;
    }
    if (all_in) continue;
    out.n = 0;
    for (int i = 0; i < P.n; ++i) {
      const int j = (i + 1) % P.n;
      const bool in_i = d[i] >= -eps, in_j = d[j] >= -eps;
      if (in_i != in_j) {
        // Exactly one endpoint outside: d[i] - d[j] is bounded away from 0.
        const double s = std::min(1.0, std::max(0.0, d[i] / (d[i] - d[j])));
        out.push({P.p[i].x + s * (P.p[j].x - P.p[i].x), P.p[i].y + s * (P.p[j].y - P.p[i].y)});
      }
      if (in_j) out.push(P.p[j]);
    }
    remove_duplicates(out, eps);
    P = out;
  }
  if (P.n < 3) P.n = 0;
}

// ---------------------------------------------------------------------------
// Basis functions of an element projected onto the auxiliary plane.

struct Elem2D {
  int kind = TRI;
  double v[4][2]{};  // projected vertices, VTK order (not reordered)
  // TRI: lambda_{1,2} = A (x - v0) with A = [v1 - v0, v2 - v0]^{-1}.
  // QUAD: x(xi, eta) = v0 + xi a + eta b + xi eta c, and A = J(1/2, 1/2)^{-1}.
  double a[2]{}, b[2]{}, c[2]{}, xc[2]{};
  double i00 = 0, i01 = 0, i10 = 0, i11 = 0;

  // False if the projected element is degenerate (no basis can be evaluated).
  bool init() {
    double j00, j01, j10, j11;
    if (kind == TRI) {
      j00 = v[1][0] - v[0][0], j01 = v[2][0] - v[0][0];
      j10 = v[1][1] - v[0][1], j11 = v[2][1] - v[0][1];
    } else {
      for (int d = 0; d < 2; ++d) {
        a[d] = v[1][d] - v[0][d];
        b[d] = v[3][d] - v[0][d];
        c[d] = v[0][d] - v[1][d] + v[2][d] - v[3][d];
        xc[d] = v[0][d] + 0.5 * (a[d] + b[d]) + 0.25 * c[d];
      }
      j00 = a[0] + 0.5 * c[0], j01 = b[0] + 0.5 * c[0];
      j10 = a[1] + 0.5 * c[1], j11 = b[1] + 0.5 * c[1];
    }
    const double det = j00 * j11 - j01 * j10;
    if (det == 0.0) return false;
    i00 = j11 / det;
    i01 = -j01 / det;
    i10 = -j10 / det;
    i11 = j00 / det;
    return true;
  }

  // Reference coordinates in a bilinear quad: Newton on x(xi) = x started at
  // the affine approximation around the centre (exact for parallelograms, so
  // one confirming step there). This is invert_quad (basis.hpp) with a better
  // start and a quadratic-convergence stopping rule: after a step of size
  // delta the error is O(delta^2), so delta < 1e-10 leaves ~1e-20. It is the
  // hot spot of quad assembly, hence the specialisation.
  void invert(const P2& x, double* xi) const {
    const double r0 = x.x - xc[0], r1 = x.y - xc[1];
    xi[0] = 0.5 + i00 * r0 + i01 * r1;
    xi[1] = 0.5 + i10 * r0 + i11 * r1;
    for (int it = 0; it < 30; ++it) {
      const double f0 = v[0][0] + xi[0] * a[0] + xi[1] * b[0] + xi[0] * xi[1] * c[0] - x.x;
      const double f1 = v[0][1] + xi[0] * a[1] + xi[1] * b[1] + xi[0] * xi[1] * c[1] - x.y;
      const double j00 = a[0] + xi[1] * c[0], j01 = b[0] + xi[0] * c[0];
      const double j10 = a[1] + xi[1] * c[1], j11 = b[1] + xi[0] * c[1];
      const double det = j00 * j11 - j01 * j10;
      if (det == 0.0) break;
      const double d0 = (j11 * f0 - j01 * f1) / det, d1 = (-j10 * f0 + j00 * f1) / det;
      xi[0] -= d0;
      xi[1] -= d1;
      if (std::max(std::fabs(d0), std::fabs(d1)) < 1e-10) break;
    }
  }

  // P1: barycentric coordinates (lambda_0 = 1 - lambda_1 - lambda_2, so the
  // values sum to 1 to rounding); Q1: bilinear basis at the inverse image.
  void eval(const P2& x, double* phi) const {
    if (kind == TRI) {
      const double dx = x.x - v[0][0], dy = x.y - v[0][1];
      const double l1 = i00 * dx + i01 * dy, l2 = i10 * dx + i11 * dy;
      phi[0] = 1.0 - l1 - l2;
      phi[1] = l1;
      phi[2] = l2;
    } else {
      double xi[2];
      invert(x, xi);
      q1_quad(xi[0], xi[1], phi);
    }
  }
};

// Unnormalised normal: triangle cross(v1 - v0, v2 - v0); quadrilateral the
// cross product of the diagonals (both have length 2 * area when planar).
inline Vec3 raw_normal(const ElementSet& e, int64_t c) {
  const Vec3 v0 = e.vertex(c, 0), v1 = e.vertex(c, 1), v2 = e.vertex(c, 2);
  if (e.kind == TRI) return cross(sub(v1, v0), sub(v2, v0));
  return cross(sub(v2, v0), sub(e.vertex(c, 3), v1));
}

// Largest vertex-vertex distance.
inline double diameter(const Vec3* v, int nv) {
  double h2 = 0.0;
  for (int i = 0; i < nv; ++i)
    for (int j = i + 1; j < nv; ++j) {
      const Vec3 d = sub(v[i], v[j]);
      h2 = std::max(h2, dot(d, d));
    }
  return std::sqrt(h2);
}

}  // namespace
}  // namespace vc
