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

// Clip a union of tets by one half-space; `eps` is the distance below which a
// vertex counts as lying on the plane (kept), so coplanar faces give no slivers.
void clip_plane(const std::vector<Tet>& in, const Plane& pl, double eps, std::vector<Tet>& out) {
  out.clear();
  for (const Tet& t : in) {
    double s[4];
    int inside[4], outside[4], ni = 0, no = 0;
    for (int k = 0; k < 4; ++k) {
      s[k] = dot(pl.n, t.v[k]) - pl.d;
      if (s[k] > eps)
        outside[no++] = k;
      else
        inside[ni++] = k;
    }
    if (no == 0) {
      out.push_back(t);
      continue;
    }
    if (ni == 0) continue;
    auto cut = [&](int i, int o) {
      const double si = std::min(s[i], 0.0);
      return lerp(t.v[i], t.v[o], si / (si - s[o]));
    };
    if (ni == 1) {
      const int i = inside[0];
      out.push_back(Tet{{t.v[i], cut(i, outside[0]), cut(i, outside[1]), cut(i, outside[2])}});
    } else {
      // A prism (a, b, c | a', b', c') with planar faces; three tets.
      Vec3 a, b, c, a2, b2, c2;
      if (ni == 3) {
        const int o = outside[0];
        a = t.v[inside[0]]; b = t.v[inside[1]]; c = t.v[inside[2]];
        a2 = cut(inside[0], o); b2 = cut(inside[1], o); c2 = cut(inside[2], o);
      } else {
        const int i = inside[0], j = inside[1], o1 = outside[0], o2 = outside[1];
        a = t.v[i]; b = cut(i, o1); c = cut(i, o2);
        a2 = t.v[j]; b2 = cut(j, o1); c2 = cut(j, o2);
      }
      out.push_back(Tet{{a, b, c, a2}});
      out.push_back(Tet{{b, c, a2, b2}});
      out.push_back(Tet{{c, a2, b2, c2}});
    }
  }
}

struct ClipBuffers {
  std::vector<Tet> a, b, pieces;
};

// Pieces of (union of `subject` tets) inside convex `c`, appended to buf.pieces.
void clip_convex(const Tet* subject, int nsubject, const Convex& c, double eps, ClipBuffers& buf) {
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
  buf.a.assign(subject, subject + nsubject);
  for (int p = 0; p < c.nplanes && !buf.a.empty(); ++p) {
    clip_plane(buf.a, c.p[p], eps, buf.b);
    std::swap(buf.a, buf.b);
  }
  buf.pieces.insert(buf.pieces.end(), buf.a.begin(), buf.a.end());
}

}  // namespace

AssemblyResult assemble_volume(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule,
                               bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                               const GridInfo* src_grid, int nthreads) {
  AssemblyResult result(tgt.ncells);
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
      search.for_each(search_box, 1e-10 * h, stamp, t, [&](int64_t s) {
        ++tested;
        sg.build(src, s, origin, false);
        // Clip the tets of the element with fewer of them by the convex pieces
        // of the other (fewest tet-piece pairs).
        const bool clip_source = sg.ntets * tg.convex_count() <= tg.ntets * sg.convex_count();
        const ElementGeometry& subj = clip_source ? sg : tg;
        ElementGeometry& clipper = clip_source ? tg : sg;
        clipper.build_planes();
        const double eps = 1e-12 * std::min(h, sg.box.diagonal()) + 4 * DBL_EPSILON * h;
        buf.pieces.clear();
        for (int c = 0; c < clipper.nconvex; ++c) clip_convex(subj.tets, subj.ntets, clipper.convex[c], eps, buf);
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
  result.collect(Bparts, Dparts, n_tgt_dofs, nth);
  return result;
}

}  // namespace vc
