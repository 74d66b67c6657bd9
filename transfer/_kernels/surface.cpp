// Surface-surface assembly by mortar segmentation (paper 2.1-2.2).
//
// Source and target are surfaces embedded in 3D made of triangles (TRI) or
// bilinear quadrilaterals (QUAD, VTK order), possibly curved and non-matching.
// For every target element t we assemble its rows of the coupling matrices of
// the L2 projection, paper eq. (3), or of the mortar projection, eq. (9):
//
//     B_ai = int_{t} phi^t_a phi^s_i dgamma,    D_ab = int_{t} phi^t_a phi^t_b dgamma,
//
// with the segmentation used in mortar contact (Puso & Laursen 2004,
// Popp et al. 2010):
//   1. auxiliary plane of t: centroid c_t, unit normal n_t, orthonormal
//      in-plane basis (e1, e2);
//   2. candidate source elements s from a bin grid over the source boxes;
//   3. keep s if it is nearly parallel, |n_s . n_t| >= min_normal_cos (both
//      orientations: contact surfaces face each other), and within
//      search_distance of the plane along n_t;
//   4. project t and s orthogonally onto the plane (2D coordinates in
//      (e1, e2)) and clip the polygon of s against the convex polygon of t
//      (Sutherland-Hodgman);
//   5. split the clipped polygon into triangles and integrate with the
//      simplex rule; at a quadrature point x the basis functions are those of
//      the projected elements evaluated at x (barycentric coordinates on
//      triangles, inverse bilinear map on quads).
// The integrals are therefore over the projection of t onto its own plane,
// which is t itself for planar elements. Because the projections of the
// (non-folding) source elements tile the projection of t, the partition of
// unity of the source basis holds pointwise: D_lumped^{-1} B 1 = 1 on every
// covered target dof, also on curved surfaces.
//
// All geometric tolerances are relative to the diameter h of the target
// element, so results are scale invariant: coplanar and coincident geometry
// (shared vertices, shared edges, elements touching along an edge) yields
// empty or zero-area pieces that are dropped, never NaN.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "surface2d.hpp"

namespace vc {
namespace {

// Relative tolerances (multiplied by the target element diameter h).
constexpr double kGeomTol = 1e-12;    // points within kGeomTol*h of a line are on it
constexpr double kAreaTol = 1e-14;    // pieces of area <= kAreaTol*h^2 are dropped
constexpr double kSearchTol = 1e-10;  // slack added to search_distance (boxes, band)

// ---------------------------------------------------------------------------
// Uniform bin grid over the source element boxes, stored sparsely: the
// nonempty bins (linear key i + nx * (j + ny * k)) sorted, with their element
// lists. Memory is proportional to the number of (element, bin) entries, not
// to the number of bins, so surfaces in a large 3D box cost nothing extra.

class BinGrid {
 public:
  void build(const std::vector<BBox>& boxes, double mean_diam) {
    keys_.clear();
    start_.assign(1, 0);
    items_.clear();
    if (boxes.empty()) return;
    BBox all;
    for (const BBox& b : boxes) {
      all.grow(b.lo);
      all.grow(b.hi);
    }
    lo_ = all.lo;
    hi_ = all.hi;
    double ext = 0.0;
    for (int d = 0; d < 3; ++d) ext = std::max(ext, hi_[d] - lo_[d]);
    // Bin size ~ mean element diameter; at most 2^20 bins per direction (the
    // key stays below 2^62); doubled while elements would be registered in
    // too many bins on average (a few huge elements among small ones).
    h_ = mean_diam > 0.0 ? mean_diam : (ext > 0.0 ? ext : 1.0);
    h_ = std::max(h_, ext * 0x1p-20);
    const size_t max_entries = 16 * boxes.size() + 1024;
    for (int attempt = 0; attempt < 64; ++attempt) {
      for (int d = 0; d < 3; ++d) n_[d] = static_cast<int64_t>((hi_[d] - lo_[d]) / h_) + 1;
      size_t entries = 0;
      for (const BBox& b : boxes) {
        int64_t i0[3], i1[3];
        range(b, i0, i1);
        entries += static_cast<size_t>((i1[0] - i0[0] + 1) * (i1[1] - i0[1] + 1) * (i1[2] - i0[2] + 1));
      }
      if (entries <= max_entries) break;
      h_ *= 2.0;
    }
    std::vector<std::pair<int64_t, int64_t>> kv;
    for (size_t e = 0; e < boxes.size(); ++e) {
      int64_t i0[3], i1[3];
      range(boxes[e], i0, i1);
      for (int64_t k = i0[2]; k <= i1[2]; ++k)
        for (int64_t j = i0[1]; j <= i1[1]; ++j)
          for (int64_t i = i0[0]; i <= i1[0]; ++i) kv.emplace_back(key(i, j, k), static_cast<int64_t>(e));
    }
    std::sort(kv.begin(), kv.end());
    items_.reserve(kv.size());
    for (size_t m = 0; m < kv.size(); ++m) {
      if (m == 0 || kv[m].first != kv[m - 1].first) {
        if (m > 0) start_.push_back(static_cast<int64_t>(items_.size()));
        keys_.push_back(kv[m].first);
      }
      items_.push_back(kv[m].second);
    }
    start_.push_back(static_cast<int64_t>(items_.size()));
  }

  // Calls f(e) for every element registered in a bin touched by box q (an
  // element may be reported several times; the caller dedupes).
  template <class F>
  void query(const BBox& q, F&& f) const {
    if (keys_.empty()) return;
    for (int d = 0; d < 3; ++d)
      if (q.hi[d] < lo_[d] || q.lo[d] > hi_[d]) return;
    int64_t i0[3], i1[3];
    range(q, i0, i1);
    const double nbins = double(i1[0] - i0[0] + 1) * double(i1[1] - i0[1] + 1) * double(i1[2] - i0[2] + 1);
    if (nbins > double(keys_.size())) {
      // Query box larger than the occupied part of the grid: scan the
      // nonempty bins instead of the box.
      for (size_t m = 0; m < keys_.size(); ++m) {
        const int64_t kk = keys_[m], i = kk % n_[0], j = (kk / n_[0]) % n_[1], k = kk / (n_[0] * n_[1]);
        if (i < i0[0] || i > i1[0] || j < i0[1] || j > i1[1] || k < i0[2] || k > i1[2]) continue;
        for (int64_t p = start_[m]; p < start_[m + 1]; ++p) f(items_[p]);
      }
      return;
    }
    // One binary search per (j, k) row; bins of a row have consecutive keys.
    for (int64_t k = i0[2]; k <= i1[2]; ++k)
      for (int64_t j = i0[1]; j <= i1[1]; ++j) {
        const int64_t k0 = key(i0[0], j, k), k1 = key(i1[0], j, k);
        auto it = std::lower_bound(keys_.begin(), keys_.end(), k0);
        for (; it != keys_.end() && *it <= k1; ++it) {
          const size_t m = static_cast<size_t>(it - keys_.begin());
          for (int64_t p = start_[m]; p < start_[m + 1]; ++p) f(items_[p]);
        }
      }
  }

 private:
  int64_t key(int64_t i, int64_t j, int64_t k) const { return i + n_[0] * (j + n_[1] * k); }
  int64_t index(double x, int d) const {
    const double r = std::floor((x - lo_[d]) / h_);
    if (!(r > 0.0)) return 0;  // also NaN
    return std::min(static_cast<int64_t>(std::min(r, 9e15)), n_[d] - 1);
  }
  void range(const BBox& b, int64_t* i0, int64_t* i1) const {
    for (int d = 0; d < 3; ++d) {
      i0[d] = index(b.lo[d], d);
      i1[d] = index(b.hi[d], d);
    }
  }

  Vec3 lo_{}, hi_{};
  double h_ = 1.0;
  int64_t n_[3] = {1, 1, 1};
  std::vector<int64_t> keys_, start_, items_;
};

void check_set(const ElementSet& e, int64_t n_dofs, const char* name) {
  const std::string who(name);
  if (e.kind != TRI && e.kind != QUAD) throw std::invalid_argument(who + ": surface kernels need TRI or QUAD cells");
  if (e.nverts != (e.kind == TRI ? 3 : 4))
    throw std::invalid_argument(who + ": cells have the wrong number of vertices for their kind");
  if (e.degree == 0 && e.ncells > n_dofs) throw std::invalid_argument(who + ": fewer dofs than cells (P0)");
  const int64_t nidx = e.ncells * e.nverts;
  for (int64_t k = 0; k < nidx; ++k) {
    const int64_t v = e.cells[k];
    if (v < 0 || v >= e.npoints || (e.degree == 1 && v >= n_dofs))
      throw std::invalid_argument(who + ": cell vertex index out of range");
  }
}

}  // namespace

AssemblyResult assemble_surface(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule,
                                bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                                double search_distance, double min_normal_cos, int nthreads) {
  check_set(src, n_src_dofs, "source");
  check_set(tgt, n_tgt_dofs, "target");
  if (rule.nbary != 3 || rule.npts <= 0) throw std::invalid_argument("surface rule needs 3 barycentric coordinates");
  search_distance = std::max(0.0, search_distance);

  const int nth = thread_count(nthreads);
  AssemblyResult result(tgt.ncells);

  // Source side, once: boxes, unit normals (zero if degenerate), bin grid.
  const int64_t ns_cells = src.ncells;
  std::vector<BBox> sbox(ns_cells);
  std::vector<Vec3> snormal(ns_cells);
  double diam_sum = 0.0;
#pragma omp parallel for num_threads(nth) reduction(+ : diam_sum)
  for (int64_t s = 0; s < ns_cells; ++s) {
    BBox b;
    for (int k = 0; k < src.nverts; ++k) b.grow(src.vertex(s, k));
    sbox[s] = b;
    diam_sum += b.diagonal();
    const Vec3 n = raw_normal(src, s);
    const double len = norm(n);
    snormal[s] = len > 0.0 ? scale(n, 1.0 / len) : Vec3{0.0, 0.0, 0.0};
  }
  BinGrid grid;
  grid.build(sbox, ns_cells > 0 ? diam_sum / double(ns_cells) : 0.0);

  const int nt = tgt.nbasis(), nsb = src.nbasis();
  const int tnv = tgt.nverts, snv = src.nverts;
  std::vector<RowPieces> Bparts(nth), Dparts(nth);
  int64_t tested = 0, intersected = 0;

#pragma omp parallel num_threads(nth) reduction(+ : tested, intersected)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    RowPieces& Bt = Bparts[tid];
    RowPieces& Dt = Dparts[tid];
    std::vector<int32_t> slot(static_cast<size_t>(n_src_dofs), -1);
    std::vector<int64_t> stamp(static_cast<size_t>(ns_cells), -1);
    std::vector<int64_t> cand;
    LocalAssembly la;
    int64_t tdofs[4], sdofs[4];
    double phi_t[4], phi_s[4], block[16];

#pragma omp for schedule(dynamic, 64)
    for (int64_t t = 0; t < tgt.ncells; ++t) {
      la.reset(nt, &slot);
      tgt.dofs(t, tdofs);

      // 1. Auxiliary plane: c_t, n_t, (e1, e2) with e1 x e2 = n_t.
      Vec3 tv[4];
      Vec3 ct{0.0, 0.0, 0.0};
      BBox tbox;
      for (int k = 0; k < tnv; ++k) {
        tv[k] = tgt.vertex(t, k);
        ct = add(ct, tv[k]);
        tbox.grow(tv[k]);
      }
      ct = scale(ct, 1.0 / tnv);
      const double h = diameter(tv, tnv);
      const Vec3 nraw = raw_normal(tgt, t);
      const double nlen = norm(nraw);
      if (!(h > 0.0) || !(nlen > kGeomTol * h * h)) {
        // Degenerate target element: no measure, nothing couples.
        continue;
      }
      const Vec3 n_t = scale(nraw, 1.0 / nlen);
      // e1 along the longest edge (a quad may have a collapsed edge), made
      // exactly orthogonal to n_t.
      Vec3 e1{0.0, 0.0, 0.0};
      for (int k = 0; k < tnv; ++k) {
        Vec3 edge = sub(tv[(k + 1) % tnv], tv[k]);
        edge = sub(edge, scale(n_t, dot(edge, n_t)));
        if (dot(edge, edge) > dot(e1, e1)) e1 = edge;
      }
      e1 = scale(e1, 1.0 / norm(e1));  // nonzero: the element has a nonzero normal
      const Vec3 e2 = cross(n_t, e1);
      auto to2d = [&](const Vec3& x) {
        const Vec3 r = sub(x, ct);
        return P2{dot(r, e1), dot(r, e2)};
      };

      // Projected target: basis element (VTK order) and CCW clip polygon.
      const double eps = kGeomTol * h;
      const double area_tol = kAreaTol * h * h;
      Elem2D te;
      te.kind = tgt.kind;
      Poly tpoly;
      for (int k = 0; k < tnv; ++k) {
        const P2 q = to2d(tv[k]);
        te.v[k][0] = q.x;
        te.v[k][1] = q.y;
        tpoly.push(q);
      }
      double tarea2 = twice_area(tpoly);
      if (tarea2 < 0.0) {
        reverse(tpoly);
        tarea2 = -tarea2;
      }
      // 6. Target measure: area of the projected target polygon.
      const double measure = 0.5 * tarea2;
      result.measure[t] = measure;
      if (!(measure > area_tol) || !te.init()) {
        continue;
      }
      P2 tmin{1e300, 1e300}, tmax{-1e300, -1e300};
      for (int k = 0; k < tpoly.n; ++k) {
        tmin = {std::min(tmin.x, tpoly.p[k].x), std::min(tmin.y, tpoly.p[k].y)};
        tmax = {std::max(tmax.x, tpoly.p[k].x), std::max(tmax.y, tpoly.p[k].y)};
      }

      // 2. Candidates: bins touched by the target box inflated by the search
      //    distance; deduplicated with the per-thread stamp.
      const double band = search_distance + kSearchTol * h;
      BBox qbox = tbox;
      for (int d = 0; d < 3; ++d) {
        qbox.lo[d] -= band;
        qbox.hi[d] += band;
      }
      cand.clear();
      grid.query(qbox, [&](int64_t s) {
        if (stamp[s] != t) {
          stamp[s] = t;
          cand.push_back(s);
        }
      });

      for (const int64_t s : cand) {
        ++tested;
        if (!sbox[s].overlaps(qbox, 0.0)) continue;

        // 3. Normal and distance filters.
        if (std::fabs(dot(snormal[s], n_t)) < min_normal_cos) continue;
        Vec3 sv[4];
        double dmin = 1e300, dmax = -1e300;
        for (int k = 0; k < snv; ++k) {
          sv[k] = src.vertex(s, k);
          const double dist = dot(sub(sv[k], ct), n_t);
          dmin = std::min(dmin, dist);
          dmax = std::max(dmax, dist);
        }
        // Signed distances of both signs: s crosses the plane (distance 0).
        const double gap = (dmin <= 0.0 && dmax >= 0.0) ? 0.0 : std::min(std::fabs(dmin), std::fabs(dmax));
        if (gap > band) continue;

        // 4. Project s onto the plane; clip its CCW polygon by the target's.
        Elem2D se;
        se.kind = src.kind;
        Poly poly;
        P2 smin{1e300, 1e300}, smax{-1e300, -1e300};
        for (int k = 0; k < snv; ++k) {
          const P2 q = to2d(sv[k]);
          se.v[k][0] = q.x;
          se.v[k][1] = q.y;
          poly.push(q);
          smin = {std::min(smin.x, q.x), std::min(smin.y, q.y)};
          smax = {std::max(smax.x, q.x), std::max(smax.y, q.y)};
        }
        if (smin.x > tmax.x + eps || smax.x < tmin.x - eps || smin.y > tmax.y + eps || smax.y < tmin.y - eps)
          continue;
        const double sarea2 = twice_area(poly);
        if (std::fabs(sarea2) <= 2.0 * area_tol) continue;  // s seen edge-on
        if (sarea2 < 0.0) reverse(poly);  // opposite orientation (facing surfaces)
        clip_convex(poly, tpoly, eps);
        if (poly.n < 3) continue;
        const double area = 0.5 * twice_area(poly);
        if (!(area > area_tol)) continue;  // touching along an edge or a vertex
        if (!se.init()) continue;
        ++intersected;
        src.dofs(s, sdofs);
        std::fill(block, block + nsb * nt, 0.0);

        // 5. Quadrature on the pieces: x = sum_k bary_k * corner_k, weight
        //    w_q * |piece|; B and M gain w phi^t_a phi^s_i and w phi^t_a phi^t_b.
        auto integrate = [&](const P2& a, const P2& b, const P2& c, double piece_area) {
          for (int q = 0; q < rule.npts; ++q) {
            const double* l = rule.bary.data() + 3 * q;
            const P2 x{l[0] * a.x + l[1] * b.x + l[2] * c.x, l[0] * a.y + l[1] * b.y + l[2] * c.y};
            if (nt == 1)
              phi_t[0] = 1.0;
            else
              te.eval(x, phi_t);
            if (nsb == 1)
              phi_s[0] = 1.0;
            else
              se.eval(x, phi_s);
            la.add_point(rule.weights[q] * piece_area, phi_t, phi_s, nsb, block);
          }
        };
        if (poly.n == 3) {
          integrate(poly.p[0], poly.p[1], poly.p[2], area);
        } else {
          // Fan from the vertex average m (inside: the piece is convex). The
          // areas are signed, which keeps the decomposition exact should a
          // non-convex projected source quad make the piece non-convex.
          P2 m{0.0, 0.0};
          for (int k = 0; k < poly.n; ++k) {
            m.x += poly.p[k].x;
            m.y += poly.p[k].y;
          }
          m = {m.x / poly.n, m.y / poly.n};
          for (int k = 0; k < poly.n; ++k) {
            const P2& a = poly.p[k];
            const P2& b = poly.p[(k + 1) % poly.n];
            const double sub_area = 0.5 * cross2(sub2(a, m), sub2(b, m));
            if (sub_area != 0.0) integrate(m, a, b, sub_area);
          }
        }
        la.add_block(sdofs, nsb, block);
      }

      // 7. Emit; the dual basis (eq. 4) only on fully covered elements.
      result.overlap[t] = la.overlap;
      la.finish(tdofs, measure, dual, lump, Bt, Dt);
    }
  }

  result.pairs_tested = tested;
  result.pairs_intersected = intersected;
  result.collect(Bparts, Dparts, n_src_dofs, n_tgt_dofs, nth);
  return result;
}

}  // namespace vc
