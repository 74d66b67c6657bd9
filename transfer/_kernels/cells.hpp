// Cells of volume meshes as the kernels see them: tetrahedra, hexahedra and
// axis-aligned boxes as unions of tets and of convex pieces (half-spaces), their
// basis functions at physical points, and the search for source cells that may
// overlap a target bounding box. Shared by volume.cpp (volume-volume) and
// trace.cpp (volume-surface).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "basis.hpp"
#include "common.hpp"

namespace vc {
namespace {

struct Tet {
  Vec3 v[4];
};

struct Plane {
  Vec3 n;    // unit outward normal
  double d;  // inside: n.x <= d
};

struct Convex {
  int nplanes = 0;
  Plane p[6];
};

constexpr int kHexTets[6][4] = {{0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6},
                                {0, 7, 4, 6}, {0, 4, 5, 6}, {0, 5, 1, 6}};

inline double tet_volume(const Tet& t) {
  return std::fabs(dot(sub(t.v[1], t.v[0]), cross(sub(t.v[2], t.v[0]), sub(t.v[3], t.v[0])))) / 6.0;
}

inline Convex tet_planes(const Tet& t) {
  static constexpr int opp[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  Convex c;
  c.nplanes = 4;
  for (int i = 0; i < 4; ++i) {
    const Vec3& a = t.v[opp[i][0]];
    Vec3 n = cross(sub(t.v[opp[i][1]], a), sub(t.v[opp[i][2]], a));
    if (dot(n, sub(t.v[i], a)) > 0) n = scale(n, -1.0);
    n = scale(n, 1.0 / norm(n));
    c.p[i] = {n, dot(n, a)};
  }
  return c;
}

// An element seen as a union of tets and a union of convex pieces.
struct ElementGeometry {
  int ntets = 0;
  Tet tets[6];
  int nconvex = 0;
  Convex convex[6];
  BBox box;
  Vec3 verts[8];
  double measure = 0.0;
  int kind = TET;

  // Coordinates relative to `origin` (a vertex of the target element): the
  // differences are exact for nearby points, so clipping and integration keep
  // their accuracy for meshes far from 0.
  void build(const ElementSet& e, int64_t c, const Vec3& origin, bool with_measure = true) {
    box = BBox{};
    for (int k = 0; k < e.nverts; ++k) {
      verts[k] = sub(e.vertex(c, k), origin);
      box.grow(verts[k]);
    }
    if (e.kind == TET) {
      ntets = 1;
      for (int k = 0; k < 4; ++k) tets[0].v[k] = verts[k];
    } else {
      ntets = 6;
      for (int t = 0; t < 6; ++t)
        for (int k = 0; k < 4; ++k) tets[t].v[k] = verts[kHexTets[t][k]];
    }
    measure = 0.0;
    if (with_measure)
      for (int t = 0; t < ntets; ++t) measure += tet_volume(tets[t]);
    kind = e.kind;
    nconvex = 0;
  }

  int convex_count() const { return kind == HEX ? 6 : 1; }

  // The convex pieces (half-spaces), needed only for the element that clips.
  void build_planes() {
    if (nconvex) return;
    if (kind == BOX) {
      nconvex = 1;
      convex[0].nplanes = 6;
      for (int d = 0; d < 3; ++d) {
        Vec3 n{0, 0, 0};
        n[d] = -1.0;
        convex[0].p[2 * d] = {n, -box.lo[d]};
        n[d] = 1.0;
        convex[0].p[2 * d + 1] = {n, box.hi[d]};
      }
    } else {
      nconvex = ntets;
      for (int t = 0; t < ntets; ++t) convex[t] = tet_planes(tets[t]);
    }
  }
};

// Basis functions of one element evaluated at physical points.
struct Evaluator {
  int kind = TET, degree = 1;
  Vec3 v0{}, lo{}, inv_extent{};
  double jinv[3][3]{};
  const Vec3* verts = nullptr;

  void build(const ElementSet& e, const ElementGeometry& g) {
    kind = e.kind;
    degree = e.degree;
    verts = g.verts;
    if (degree == 0) return;
    if (kind == TET) {
      v0 = g.verts[0];
      double J[3][3];
      for (int k = 0; k < 3; ++k)
        for (int d = 0; d < 3; ++d) J[d][k] = g.verts[k + 1][d] - v0[d];
      const double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                         J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                         J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          const int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
          jinv[i][j] = (J[i1][j1] * J[i2][j2] - J[i1][j2] * J[i2][j1]) / det;
        }
    } else if (kind == BOX) {
      lo = g.box.lo;
      for (int d = 0; d < 3; ++d) inv_extent[d] = 1.0 / (g.box.hi[d] - g.box.lo[d]);
    }
  }

  // Affine basis phi_a(x) = c[a] + g[a].x (degree 0 or tetrahedra).
  void affine(double* c, Vec3* g) const {
    if (degree == 0) {
      c[0] = 1.0;
      g[0] = {0, 0, 0};
      return;
    }
    const Vec3 r = scale(v0, -1.0);
    c[0] = 1.0;
    g[0] = {0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      g[i + 1] = {jinv[i][0], jinv[i][1], jinv[i][2]};
      c[i + 1] = dot(g[i + 1], r);
      c[0] -= c[i + 1];
      g[0] = sub(g[0], g[i + 1]);
    }
  }

  void eval(const Vec3& x, double* phi) const {
    if (degree == 0) {
      phi[0] = 1.0;
      return;
    }
    if (kind == TET) {
      const Vec3 r = sub(x, v0);
      double s = 0.0;
      for (int i = 0; i < 3; ++i) {
        phi[i + 1] = jinv[i][0] * r[0] + jinv[i][1] * r[1] + jinv[i][2] * r[2];
        s += phi[i + 1];
      }
      phi[0] = 1.0 - s;
    } else if (kind == BOX) {
      q1_hex((x[0] - lo[0]) * inv_extent[0], (x[1] - lo[1]) * inv_extent[1], (x[2] - lo[2]) * inv_extent[2], phi);
    } else {
      const Vec3 xi = invert_hex(verts, x);
      q1_hex(xi[0], xi[1], xi[2], phi);
    }
  }
};

// Candidate source elements of a target bounding box.
class SourceSearch {
 public:
  SourceSearch(const ElementSet& src, const GridInfo* grid) : boxes_(src.ncells), grid_(grid) {
    for (int64_t e = 0; e < src.ncells; ++e)
      for (int k = 0; k < src.nverts; ++k) boxes_[e].grow(src.vertex(e, k));
    if (grid_) return;
    BBox all;
    double mean = 0.0;
    for (const auto& b : boxes_) {
      all.grow(b.lo);
      all.grow(b.hi);
      mean += (b.hi[0] - b.lo[0]) + (b.hi[1] - b.lo[1]) + (b.hi[2] - b.lo[2]);
    }
    mean /= std::max<double>(1.0, 3.0 * boxes_.size());
    lo_ = all.lo;
    int64_t total = 1;
    for (int d = 0; d < 3; ++d) {
      const double ext = all.hi[d] - all.lo[d];
      n_[d] = std::max<int64_t>(1, static_cast<int64_t>(ext / std::max(mean, 1e-300)));
      total *= n_[d];
    }
    while (total > 4 * static_cast<int64_t>(boxes_.size()) + 64) {  // cap the bin count
      total = 1;
      for (int d = 0; d < 3; ++d) {
        n_[d] = std::max<int64_t>(1, n_[d] / 2);
        total *= n_[d];
      }
    }
    for (int d = 0; d < 3; ++d) h_[d] = std::max((all.hi[d] - all.lo[d]) / n_[d], 1e-300);
    start_.assign(total + 1, 0);
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<int64_t> fill;
      if (pass == 1) {
        for (int64_t k = 0; k < total; ++k) start_[k + 1] += start_[k];
        items_.resize(start_[total]);
        fill.assign(start_.begin(), start_.end() - 1);
      }
      for (int64_t e = 0; e < static_cast<int64_t>(boxes_.size()); ++e) {
        int64_t r[3][2] = {{0, 0}, {0, 0}, {0, 0}};
        range(boxes_[e], 0.0, r);
        for (int64_t k = r[2][0]; k <= r[2][1]; ++k)
          for (int64_t j = r[1][0]; j <= r[1][1]; ++j)
            for (int64_t i = r[0][0]; i <= r[0][1]; ++i) {
              const int64_t bin = i + n_[0] * (j + n_[1] * k);
              if (pass == 0)
                ++start_[bin + 1];
              else
                items_[fill[bin]++] = e;
            }
      }
    }
  }

  const BBox& box(int64_t e) const { return boxes_[e]; }

  // Calls f(e) once for every source element whose box may overlap `b`.
  template <class F>
  void for_each(const BBox& b, double tol, std::vector<int64_t>& stamp, int64_t tag, F&& f) const {
    int64_t r[3][2] = {{0, 0}, {0, 0}, {0, 0}};
    if (grid_) {
      for (int d = 0; d < 3; ++d) {
        const double a = (b.lo[d] - tol - grid_->origin[d]) / grid_->spacing[d];
        const double z = (b.hi[d] + tol - grid_->origin[d]) / grid_->spacing[d];
        r[d][0] = std::max<int64_t>(0, static_cast<int64_t>(std::floor(a)));
        r[d][1] = std::min<int64_t>(grid_->shape[d] - 1, static_cast<int64_t>(std::floor(z)));
        if (r[d][0] > r[d][1]) return;
      }
      for (int64_t k = r[2][0]; k <= r[2][1]; ++k)
        for (int64_t j = r[1][0]; j <= r[1][1]; ++j)
          for (int64_t i = r[0][0]; i <= r[0][1]; ++i) f(i + grid_->shape[0] * (j + grid_->shape[1] * k));
      return;
    }
    if (!range(b, tol, r)) return;
    for (int64_t k = r[2][0]; k <= r[2][1]; ++k)
      for (int64_t j = r[1][0]; j <= r[1][1]; ++j)
        for (int64_t i = r[0][0]; i <= r[0][1]; ++i) {
          const int64_t bin = i + n_[0] * (j + n_[1] * k);
          for (int64_t q = start_[bin]; q < start_[bin + 1]; ++q) {
            const int64_t e = items_[q];
            if (stamp[e] == tag) continue;
            stamp[e] = tag;
            if (boxes_[e].overlaps(b, tol)) f(e);
          }
        }
  }

 private:
  bool range(const BBox& b, double tol, int64_t r[3][2]) const {
    for (int d = 0; d < 3; ++d) {
      const double a = (b.lo[d] - tol - lo_[d]) / h_[d];
      const double z = (b.hi[d] + tol - lo_[d]) / h_[d];
      if (z < 0 || a >= n_[d]) return false;
      r[d][0] = std::clamp<int64_t>(static_cast<int64_t>(std::floor(a)), 0, n_[d] - 1);
      r[d][1] = std::clamp<int64_t>(static_cast<int64_t>(std::floor(z)), 0, n_[d] - 1);
    }
    return true;
  }

  std::vector<BBox> boxes_;
  const GridInfo* grid_;
  Vec3 lo_{}, h_{};
  int64_t n_[3] = {1, 1, 1};
  std::vector<int64_t> start_, items_;
};

}  // namespace
}  // namespace vc
