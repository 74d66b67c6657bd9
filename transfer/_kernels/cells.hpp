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

// Candidate source elements of a target bounding box. Each source cell is filed once, in
// the bin of its box's lower corner, with a copy of its box (bins in order, each a
// contiguous run): a query visits the bins of the lower corners that can overlap, the
// target box widened below by the largest source box, row by row in one sweep each,
// without duplicates to skip. A grid source is searched by its index arithmetic alone.
class SourceSearch {
 public:
  SourceSearch(const ElementSet& src, const GridInfo* grid) : src_(src), grid_(grid) {
    if (grid_) return;
    BBox all;
    double mean = 0.0;
    for (int64_t e = 0; e < src.ncells; ++e) {
      const BBox b = box_of(e);
      all.grow(b.lo);
      all.grow(b.hi);
      mean += (b.hi[0] - b.lo[0]) + (b.hi[1] - b.lo[1]) + (b.hi[2] - b.lo[2]);
      for (int d = 0; d < 3; ++d) extent_[d] = std::max(extent_[d], b.hi[d] - b.lo[d]);
    }
    mean /= std::max<double>(1.0, 3.0 * src.ncells);
    lo_ = all.lo;
    int64_t total = 1;
    for (int d = 0; d < 3; ++d) {
      const double ext = all.hi[d] - all.lo[d];
      n_[d] = std::max<int64_t>(1, static_cast<int64_t>(ext / std::max(kBinSize * mean, 1e-300)));
      total *= n_[d];
    }
    while (total > 4 * src.ncells + 64) {  // cap the bin count
      total = 1;
      for (int d = 0; d < 3; ++d) {
        n_[d] = std::max<int64_t>(1, n_[d] / 2);
        total *= n_[d];
      }
    }
    for (int d = 0; d < 3; ++d) h_[d] = std::max((all.hi[d] - all.lo[d]) / n_[d], 1e-300);
    // the boxes recomputed per pass rather than kept twice (peak memory)
    start_.assign(total + 1, 0);
    for (int64_t e = 0; e < src.ncells; ++e) ++start_[bin(box_of(e)) + 1];
    for (int64_t k = 0; k < total; ++k) start_[k + 1] += start_[k];
    filed_.resize(src.ncells);
    std::vector<int64_t> fill(start_.begin(), start_.end() - 1);
    for (int64_t e = 0; e < src.ncells; ++e) {
      const BBox b = box_of(e);
      filed_[fill[bin(b)]++] = {b, e};
    }
  }

  // Calls f(e, box of e) once for every source element whose box overlaps `b` within tol.
  template <class F>
  void for_each(const BBox& b, double tol, F&& f) const {
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
          for (int64_t i = r[0][0]; i <= r[0][1]; ++i) {
            const int64_t ijk[3] = {i, j, k};
            BBox cell;  // its corners as the grid's points are placed: origin + spacing * index
            for (int d = 0; d < 3; ++d) {
              cell.lo[d] = grid_->origin[d] + grid_->spacing[d] * static_cast<double>(ijk[d]);
              cell.hi[d] = grid_->origin[d] + grid_->spacing[d] * static_cast<double>(ijk[d] + 1);
            }
            f(i + grid_->shape[0] * (j + grid_->shape[1] * k), cell);
          }
      return;
    }
    for (int d = 0; d < 3; ++d) {
      // the lowest lower corner of an overlapping box, less a margin for its rounding
      const double first = b.lo[d] - tol - extent_[d];
      const double last = b.hi[d] + tol;
      if (last < lo_[d]) return;
      r[d][0] = cell(first - 1e-9 * (std::fabs(first) + h_[d]), d);
      r[d][1] = cell(last, d);
    }
    for (int64_t k = r[2][0]; k <= r[2][1]; ++k)
      for (int64_t j = r[1][0]; j <= r[1][1]; ++j) {
        const int64_t row = n_[0] * (j + n_[1] * k);
        for (int64_t q = start_[row + r[0][0]]; q < start_[row + r[0][1] + 1]; ++q)
          if (filed_[q].box.overlaps(b, tol)) f(filed_[q].e, filed_[q].box);
      }
  }

 private:
  // Bins of about this many mean source box sizes.
  static constexpr double kBinSize = 0.7;

  BBox box_of(int64_t e) const {
    BBox b;
    for (int k = 0; k < src_.nverts; ++k) b.grow(src_.vertex(e, k));
    return b;
  }

  // The bin of a box: that of its lower corner.
  int64_t bin(const BBox& b) const { return cell(b.lo[0], 0) + n_[0] * (cell(b.lo[1], 1) + n_[1] * cell(b.lo[2], 2)); }

  // The bin of coordinate x along axis d, clamped to the grid.
  int64_t cell(double x, int d) const {
    const double a = std::floor((x - lo_[d]) / h_[d]);
    return a < 0 ? 0 : (a >= n_[d] ? n_[d] - 1 : static_cast<int64_t>(a));
  }

  struct Filed {
    BBox box;
    int64_t e;
  };
  const ElementSet& src_;
  const GridInfo* grid_;
  Vec3 lo_{}, h_{}, extent_{0, 0, 0};
  int64_t n_[3] = {1, 1, 1};
  std::vector<int64_t> start_;
  std::vector<Filed> filed_;
};

}  // namespace
}  // namespace vc
