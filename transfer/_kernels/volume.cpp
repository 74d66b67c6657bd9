// Volume-volume coupling (paper eq. 3): exact intersection of tetrahedra,
// hexahedra and axis-aligned boxes by clipping, quadrature on the pieces.
//
// Geometry: every element is a union of tetrahedra (a tet is itself, a hex is
// six tets around its 0-6 diagonal, a box likewise) and a union of convex
// pieces given by half-spaces (a tet: 4 planes, a box: 6 planes, a hex: its six
// tets). The intersection of two elements is computed by clipping the tets of
// one against the convex pieces of the other; a tet cut by a plane is again a
// union of at most three tets, so the pieces stay tets and any simplex rule
// integrates on them.
#include <algorithm>
#include <cfloat>
#include <stdexcept>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "cells.hpp"

namespace vc {
namespace {

// Integrals of 1, x and x x^T over a union of tets (coordinates relative to the
// target element). Products of two affine functions are integrated exactly from
// them; for badly shaped elements (large basis gradients) the expansion cancels,
// and the kernel integrates by quadrature instead (see kSliverShape).
struct Moments {
  double m0 = 0.0;
  Vec3 m1{0, 0, 0};
  double m2[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};

  void add_tet(const Tet& t, double vol) {
    // int_K x_i x_j = |K|/20 (sum_k v_k,i v_k,j + s_i s_j), s = sum_k v_k
    const Vec3* v = t.v;
    Vec3 s{0, 0, 0};
    for (int k = 0; k < 4; ++k) s = add(s, v[k]);
    m0 += vol;
    m1 = add(m1, scale(s, vol / 4.0));
    const double c = vol / 20.0;
    for (int i = 0; i < 3; ++i)
      for (int j = i; j < 3; ++j) {
        double q = s[i] * s[j];
        for (int k = 0; k < 4; ++k) q += v[k][i] * v[k][j];
        m2[i][j] += c * q;
      }
  }
  void merge(const Moments& o) {
    m0 += o.m0;
    m1 = add(m1, o.m1);
    for (int i = 0; i < 3; ++i)
      for (int j = i; j < 3; ++j) m2[i][j] += o.m2[i][j];
  }
  // Integrals int phi_a psi_i of two affine bases phi_a = c[a] + g[a].x (na
  // functions) and psi_i = d[i] + h[i].x (ni functions) into out[i * na + a].
  void products(int na, const double* c, const Vec3* g, int ni, const double* d, const Vec3* h,
                double* out) const {
    Vec3 mg[8];  // (int x x^T) g[a]
    double m1g[8];
    for (int a = 0; a < na; ++a) {
      mg[a] = {m2[0][0] * g[a][0] + m2[0][1] * g[a][1] + m2[0][2] * g[a][2],
               m2[0][1] * g[a][0] + m2[1][1] * g[a][1] + m2[1][2] * g[a][2],
               m2[0][2] * g[a][0] + m2[1][2] * g[a][1] + m2[2][2] * g[a][2]};
      m1g[a] = dot(m1, g[a]);
    }
    for (int i = 0; i < ni; ++i) {
      const double m1h = dot(m1, h[i]);
      for (int a = 0; a < na; ++a)
        out[i * na + a] = c[a] * d[i] * m0 + c[a] * m1h + d[i] * m1g[a] + dot(h[i], mg[a]);
    }
  }
};

bool is_affine(const ElementSet& e) { return e.degree == 0 || e.kind == TET; }

// Above this size of h * |grad phi| (about 2 to 5 on shapely tets) moments lose
// digits to cancellation; such pairs are integrated with kDegree2.
constexpr double kSliverShape = 100.0;

// The 4-point rule exact for degree 2 on a tetrahedron.
const SimplexRule kDegree2 = [] {
  SimplexRule r;
  r.npts = 4;
  r.nbary = 4;
  const double a = 0.1381966011250105, b = 1.0 - 3.0 * a;
  for (int q = 0; q < 4; ++q)
    for (int k = 0; k < 4; ++k) r.bary.push_back(k == q ? b : a);
  r.weights.assign(4, 0.25);
  return r;
}();

double shape(const Vec3* g, int n, double h) {
  double gmax = 0.0;
  for (int a = 0; a < n; ++a) gmax = std::max(gmax, norm(g[a]));
  return gmax * h;
}

// A convex polyhedron clipped in place by half-spaces (after Powell and Abel's r3d,
// J. Comput. Phys. 2015): every vertex has three neighbours, ordered so that walking
// from vertex v to its neighbour k and on to that vertex's neighbour after v goes around
// a face. A plane cut removes the vertices outside, puts a new vertex on every cut edge
// and links the new vertices around the new face: no vertex is duplicated, and a piece
// is handed on as the tets fanned from vertex 0 over the faces (pieces of the same
// union as the tet-by-tet clipping gave, in fewer and larger tets).
class Polyhedron {
 public:
  // Up to 4 + 6 faces (a tet cut by a box) give 16 vertices; twice that while cutting.
  static constexpr int kMax = 40;

  void assign(const Tet& t) {
    n_ = 4;
    const bool positive = dot(sub(t.v[1], t.v[0]), cross(sub(t.v[2], t.v[0]), sub(t.v[3], t.v[0]))) > 0;
    for (int k = 0; k < 4; ++k) x_[k] = t.v[k];
    if (!positive) std::swap(x_[1], x_[2]);
    static constexpr int nb[4][3] = {{1, 3, 2}, {2, 3, 0}, {0, 3, 1}, {1, 2, 0}};
    for (int k = 0; k < 4; ++k)
      for (int j = 0; j < 3; ++j) nb_[k][j] = nb[k][j];
  }

  bool empty() const { return n_ == 0; }

  // Keep the part with n.x - d <= eps; false when nothing is left.
  bool clip(const Plane& pl, double eps) {
    double s[kMax];
    int out = 0;
    for (int v = 0; v < n_; ++v) {
      s[v] = dot(pl.n, x_[v]) - pl.d;
      out += s[v] > eps;
    }
    if (out == 0) return true;
    if (out == n_) {
      n_ = 0;
      return false;
    }
    const int old = n_;
    for (int v = 0; v < old; ++v) {
      if (s[v] > eps) continue;
      for (int k = 0; k < 3; ++k) {
        const int w = nb_[v][k];
        if (!(s[w] > eps)) continue;
        const double sv = s[v] >= -eps ? 0.0 : s[v];  // a vertex within eps lies on the plane
        x_[n_] = lerp(x_[v], x_[w], sv / (sv - s[w]));
        nb_[n_][0] = v;
        nb_[v][k] = n_;
        ++n_;
      }
    }
    for (int start = old; start < n_; ++start) {  // walk the face of each new edge
      int cur = start, next = nb_[cur][0];
      do {
        const int k = slot(next, cur);
        cur = next;
        next = nb_[cur][(k + 1) % 3];
      } while (cur < old);
      nb_[start][2] = cur;
      nb_[cur][1] = start;
    }
    int index[kMax], kept = 0;
    for (int v = 0; v < n_; ++v) {
      index[v] = (v < old && s[v] > eps) ? -1 : kept;
      if (index[v] >= 0) {
        x_[kept] = x_[v];
        for (int k = 0; k < 3; ++k) nb_[kept][k] = nb_[v][k];
        ++kept;
      }
    }
    n_ = kept;
    for (int v = 0; v < n_; ++v)
      for (int k = 0; k < 3; ++k) nb_[v][k] = index[nb_[v][k]];
    return true;
  }

  // The tets from vertex 0 to the fan triangles of every face not holding vertex 0.
  template <class F>
  void for_each_tet(F&& f) const {
    bool seen[kMax][3] = {};
    for (int start = 0; start < n_; ++start)
      for (int k0 = 0; k0 < 3; ++k0) {
        if (seen[start][k0]) continue;
        // the face to the left of edge start -> nb[start][k0]
        int cur = start, k = k0, next = nb_[cur][k];
        seen[cur][k] = true;
        bool apex = start == 0;
        int face[kMax], m = 0;
        face[m++] = start;
        while (next != start) {
          const int j = slot(next, cur);
          cur = next;
          k = (j + 1) % 3;
          seen[cur][k] = true;
          apex = apex || cur == 0;
          face[m++] = cur;
          next = nb_[cur][k];
        }
        if (apex) continue;
        for (int i = 1; i + 1 < m; ++i) f(Tet{{x_[0], x_[face[0]], x_[face[i]], x_[face[i + 1]]}});
      }
  }

 private:
  int slot(int v, int w) const { return nb_[v][0] == w ? 0 : (nb_[v][1] == w ? 1 : 2); }

  int n_ = 0;
  Vec3 x_[kMax];
  int nb_[kMax][3];
};

struct ClipBuffers {
  Polyhedron poly;
  std::vector<Tet> pieces;
};

// True when the box [lo, hi] lies outside one plane of convex `c` by more than eps
// (its corner farthest along -n is outside): nothing in the box meets `c`.
bool box_outside(const Vec3& lo, const Vec3& hi, const Convex& c, double eps) {
  for (int p = 0; p < c.nplanes; ++p) {
    const Vec3& n = c.p[p].n;
    double nearest = 0.0;
    for (int d = 0; d < 3; ++d) nearest += n[d] * (n[d] > 0 ? lo[d] : hi[d]);
    if (nearest - c.p[p].d > eps) return true;
  }
  return false;
}

// True when a face plane of tet `t` has all four vertices of tet `u` outside it (by
// more than eps): the tets are disjoint. With the test of the faces of `u`
// (clip_convex) these are eight of the separating axes of two tets.
bool separated_by_faces(const Tet& t, const Tet& u, double eps) {
  static constexpr int opp[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  for (int i = 0; i < 4; ++i) {
    const Vec3& a = t.v[opp[i][0]];
    Vec3 n = cross(sub(t.v[opp[i][1]], a), sub(t.v[opp[i][2]], a));
    if (dot(n, sub(t.v[i], a)) > 0) n = scale(n, -1.0);  // outward: the tet's own vertex is inside
    const double tol2 = eps * eps * dot(n, n);  // |s| > eps |n|, compared squared
    bool all_out = true;
    for (int k = 0; k < 4 && all_out; ++k) {
      const double s = dot(n, sub(u.v[k], a));
      all_out = s > 0 && s * s > tol2;
    }
    if (all_out) return true;
  }
  return false;
}

// Pieces of (union of `subject` tets) inside convex `c`, appended to buf.pieces; `c`
// is the tet `other` when not null (then a subject tet its faces separate is skipped).
void clip_convex(const Tet* subject, int nsubject, const Convex& c, const Tet* other, double eps,
                 ClipBuffers& buf) {
  // Quick rejection (all subject vertices outside one plane) and acceptance
  // (all inside every plane: the subject lies in the convex piece).
  bool inside_all = true;
  for (int p = 0; p < c.nplanes; ++p) {
    bool all_out = true;
    for (int t = 0; t < nsubject; ++t)
      for (int k = 0; k < 4; ++k) {
        const double s = dot(c.p[p].n, subject[t].v[k]) - c.p[p].d;
        all_out = all_out && s > eps;
        inside_all = inside_all && s <= eps;
      }
    if (all_out) return;
  }
  if (inside_all) {
    buf.pieces.insert(buf.pieces.end(), subject, subject + nsubject);
    return;
  }
  for (int t = 0; t < nsubject; ++t) {
    if (other && separated_by_faces(subject[t], *other, eps)) continue;
    buf.poly.assign(subject[t]);
    for (int p = 0; p < c.nplanes && buf.poly.clip(c.p[p], eps); ++p) {
    }
    buf.poly.for_each_tet([&](const Tet& piece) { buf.pieces.push_back(piece); });
  }
}

}  // namespace

AssemblyResult assemble_volume(const ElementSet& src_in, const ElementSet& tgt, const SimplexRule& rule,
                               bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                               const GridInfo* src_grid, int nthreads, int stages) {
  AssemblyResult result(tgt.ncells);
  ElementSet src = src_in;
  const std::vector<double> coords = src.packed_coords();
  src.cell_coords = coords.data();
  const SourceSearch search(src, src_grid);

  const int nth = thread_count(nthreads);
  std::vector<Triplets> Bparts(nth), Dparts(nth);
  int64_t tested = 0, intersected = 0;
  const int nt = tgt.nbasis(), ns = src.nbasis();
  // An empty rule asks for exact integration from moments (affine bases only).
  const bool exact = rule.npts == 0;
  if (exact && !(is_affine(src) && is_affine(tgt)))
    throw std::invalid_argument("exact (moment) integration needs affine bases: P0/P1 on tets, degree 0");

#pragma omp parallel num_threads(nth) reduction(+ : tested, intersected)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    std::vector<int32_t> slot(n_src_dofs, -1);
    Bparts[tid].reserve(8 * nt * (tgt.ncells / nth + 1));
    Dparts[tid].reserve((lump ? 1 : nt) * nt * (tgt.ncells / nth + 1));
    std::vector<int64_t> stamp(src_grid ? 0 : src.ncells, -1);
    LocalAssembly la;
    ClipBuffers buf;
    ElementGeometry tg, sg;
    Evaluator tev, sev;
    Moments pair, total;
    int64_t tdofs[8], sdofs[8];
    double phi_t[8], phi_s[8], ct[8], cs[8], block[64];
    Vec3 gt[8], gs[8];

#pragma omp for schedule(dynamic, 64)
    for (int64_t t = 0; t < tgt.ncells; ++t) {
      const Vec3 origin = tgt.vertex(t, 0);
      tg.build(tgt, t, origin);
      tev.build(tgt, tg);
      tgt.dofs(t, tdofs);
      la.reset(nt, &slot);
      total = Moments{};
      const double h = tg.box.diagonal();
      const double vmin = 1e-15 * tg.measure;
      if (exact) tev.affine(ct, gt);
      const bool moments_t = exact && shape(gt, nt, h) <= kSliverShape;
      const BBox search_box{add(tg.box.lo, origin), add(tg.box.hi, origin)};
      tg.build_planes();
      // A source box outside a plane of a convex target (a tet, a box) needs no clipping.
      const double eps_box = 1e-12 * h + 4 * DBL_EPSILON * h;
      search.for_each(search_box, 1e-10 * h, stamp, t, [&](int64_t s) {
        ++tested;
        if (stages < 2) return;
        if (tg.nconvex == 1) {
          const BBox& b = search.box(s);
          if (box_outside(sub(b.lo, origin), sub(b.hi, origin), tg.convex[0], eps_box)) return;
        }
        sg.build(src, s, origin, false);
        // Clip the tets of the element with fewer of them by the convex pieces
        // of the other (fewest tet-piece pairs).
        const bool clip_source = sg.ntets * tg.convex_count() <= tg.ntets * sg.convex_count();
        const ElementGeometry& subj = clip_source ? sg : tg;
        ElementGeometry& clipper = clip_source ? tg : sg;
        clipper.build_planes();
        const double eps = 1e-12 * std::min(h, sg.box.diagonal()) + 4 * DBL_EPSILON * h;
        buf.pieces.clear();
        const Tet* other = clipper.kind == TET ? &clipper.tets[0] : nullptr;  // its faces separate too
        for (int c = 0; c < clipper.nconvex; ++c) clip_convex(subj.tets, subj.ntets, clipper.convex[c], other, eps, buf);
        if (stages < 3) return;
        bool any = false, moments = false;
        const SimplexRule* q_rule = &rule;
        pair = Moments{};
        for (const Tet& piece : buf.pieces) {
          const double vol = tet_volume(piece);
          if (!(vol > vmin)) continue;
          if (!any) {
            sev.build(src, sg);
            src.dofs(s, sdofs);
            std::fill(block, block + ns * nt, 0.0);
            if (exact) {
              sev.affine(cs, gs);
              moments = moments_t && shape(gs, ns, sg.box.diagonal()) <= kSliverShape;
              if (!moments) q_rule = &kDegree2;
            }
            any = true;
          }
          if (moments) {
            pair.add_tet(piece, vol);
            continue;
          }
          for (int q = 0; q < q_rule->npts; ++q) {
            const double* l = &q_rule->bary[4 * q];
            Vec3 x{0, 0, 0};
            for (int k = 0; k < 4; ++k) x = add(x, scale(piece.v[k], l[k]));
            tev.eval(x, phi_t);
            sev.eval(x, phi_s);
            la.add_point(q_rule->weights[q] * vol, phi_t, phi_s, ns, block);
          }
        }
        if (!any) return;
        ++intersected;
        if (moments) {  // B block from the moments of the intersection
          pair.products(nt, ct, gt, ns, cs, gs, block);
          total.merge(pair);
        }
        la.add_block(sdofs, ns, block);
      });
      if (total.m0 > 0.0) {  // target mass over the overlap, from the summed moments
        double mass[64];
        total.products(nt, ct, gt, nt, ct, gt, mass);
        for (int k = 0; k < nt * nt; ++k) la.m[k] += mass[k];
        la.overlap += total.m0;
      }
      result.measure[t] = tg.measure;
      result.overlap[t] = la.overlap;
      la.finish(tdofs, tg.measure, dual, lump, Bparts[tid], Dparts[tid]);
    }
  }
  result.pairs_tested = tested;
  result.pairs_intersected = intersected;
  result.collect(Bparts, Dparts, n_src_dofs, n_tgt_dofs, nth);
  return result;
}

}  // namespace vc
