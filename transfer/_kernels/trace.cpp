// Volume-surface coupling: the L2 projection of a volume field onto a surface
// inside the volume mesh (paper eq. 3 with W a space on a surface Gamma, e.g.
// the fluid pressure on the fracture faces of the solid, paper 2.3 Steps 2-3):
//
//     B_ai = int_{Gamma} phi^t_a phi^s_i dgamma,   D_ab = int_{Gamma ∩ source} phi^t_a phi^t_b.
//
// Every target triangle (a quadrilateral: two triangles) is clipped in 3D by
// the half-spaces of the convex pieces of each source cell it meets (a tet, a
// box, the six tets of a hexahedron); the pieces are planar polygons, split
// into triangles from their first vertex and integrated with the triangle
// rule. Target basis functions are evaluated in the element's own plane, the
// source ones at the 3D quadrature points. A piece lying in a face of a source
// cell belongs to the cell that contains the points just beside it along
// kTieBreak, or, on the boundary of the source mesh where there is none, to
// the cell itself: a face shared by two cells is counted once.
#include <algorithm>
#include <cfloat>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "cells.hpp"
#include "surface2d.hpp"

namespace vc {
namespace {

constexpr int kMaxPoly3 = 24;
const Vec3 kTieBreak = {0.6, 0.48, 0.64};  // unit, along no axis and no simple diagonal

struct Poly3 {
  Vec3 p[kMaxPoly3];
  int n = 0;
  void push(const Vec3& q) {
    if (n < kMaxPoly3) p[n++] = q;
  }
};

enum class Clip { kept, empty, in_face };

// Keep the part of the planar polygon P in n.x <= d (Sutherland-Hodgman in 3D).
// A polygon lying in the plane itself is `in_face` when the points beside it
// along kTieBreak are outside this cell (the neighbour across the face, if
// any, owns it) and kept otherwise.
Clip clip_half_space(Poly3& P, const Plane& pl, double eps) {
  double s[kMaxPoly3];
  bool all_in = true, all_on = true, all_out = true;
  for (int i = 0; i < P.n; ++i) {
    s[i] = dot(pl.n, P.p[i]) - pl.d;
    all_in = all_in && s[i] <= eps;
    all_on = all_on && std::fabs(s[i]) <= eps;
    all_out = all_out && s[i] > eps;
  }
  if (all_on) return dot(pl.n, kTieBreak) > 0 ? Clip::in_face : Clip::kept;
  if (all_in) return Clip::kept;
  if (all_out) {
    P.n = 0;
    return Clip::empty;
  }
  Poly3 out;
  for (int i = 0; i < P.n; ++i) {
    const int j = (i + 1) % P.n;
    const bool in_i = s[i] <= eps, in_j = s[j] <= eps;
    if (in_i) out.push(P.p[i]);
    if (in_i != in_j) {
      const double t = std::min(1.0, std::max(0.0, s[i] / (s[i] - s[j])));
      out.push(lerp(P.p[i], P.p[j], t));
    }
  }
  P = out;
  return P.n >= 3 ? Clip::kept : Clip::empty;
}

bool inside(const ElementGeometry& g, const Vec3& x, double eps) {
  for (int c = 0; c < g.nconvex; ++c) {
    bool in = true;
    for (int p = 0; p < g.convex[c].nplanes && in; ++p) in = dot(g.convex[c].p[p].n, x) - g.convex[c].p[p].d <= eps;
    if (in) return true;
  }
  return false;
}

}  // namespace

AssemblyResult assemble_trace(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule, bool dual,
                              bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs, const GridInfo* src_grid,
                              int nthreads) {
  AssemblyResult result(tgt.ncells);
  const SourceSearch search(src, src_grid);

  const int nth = thread_count(nthreads);
  std::vector<RowPieces> Bparts(nth), Dparts(nth);
  int64_t tested = 0, intersected = 0;
  const int nt = tgt.nbasis(), ns = src.nbasis();
  static constexpr int kTris[2][3] = {{0, 1, 2}, {0, 2, 3}};

#pragma omp parallel num_threads(nth) reduction(+ : tested, intersected)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    std::vector<int32_t> slot(n_src_dofs, -1);
    LocalAssembly la;
    ElementGeometry sg, other;
    Evaluator sev;
    Elem2D te;
    int64_t tdofs[8], sdofs[8];
    double phi_t[8], phi_s[8], block[64];
    Vec3 tv[4];

#pragma omp for schedule(dynamic, 64)
    for (int64_t t = 0; t < tgt.ncells; ++t) {
      la.reset(nt, &slot);
      tgt.dofs(t, tdofs);
      const Vec3 origin = tgt.vertex(t, 0);
      BBox box;
      for (int k = 0; k < tgt.nverts; ++k) {
        tv[k] = sub(tgt.vertex(t, k), origin);
        box.grow(tv[k]);
      }
      const int ntris = tgt.kind == QUAD ? 2 : 1;
      double measure = 0.0;
      for (int k = 0; k < ntris; ++k)
        measure += 0.5 * norm(cross(sub(tv[kTris[k][1]], tv[kTris[k][0]]), sub(tv[kTris[k][2]], tv[kTris[k][0]])));
      const double h = box.diagonal();
      result.measure[t] = measure;
      // The element's plane: target basis functions live there.
      const Vec3 nraw = raw_normal(tgt, t);
      if (!(measure > 1e-14 * h * h) || !(norm(nraw) > 0)) continue;
      const Vec3 n = scale(nraw, 1.0 / norm(nraw));
      Vec3 e1 = sub(tv[1], scale(n, dot(tv[1], n)));
      e1 = scale(e1, 1.0 / norm(e1));
      const Vec3 e2 = cross(n, e1);
      te.kind = tgt.kind;
      for (int k = 0; k < tgt.nverts; ++k) {
        te.v[k][0] = dot(tv[k], e1);
        te.v[k][1] = dot(tv[k], e2);
      }
      if (nt > 1 && !te.init()) continue;
      const double eps = 1e-12 * h + 4 * DBL_EPSILON * h;
      const BBox search_box{add(box.lo, origin), add(box.hi, origin)};
      search.for_each(search_box, 1e-10 * h, [&](int64_t s, const BBox&) {
        ++tested;
        sg.build(src, s, origin, false);
        sg.build_planes();
        bool any = false;
        for (int c = 0; c < sg.nconvex; ++c)
          for (int k = 0; k < ntris; ++k) {
            Poly3 P;
            for (int v = 0; v < 3; ++v) P.push(tv[kTris[k][v]]);
            bool keep = true, in_face = false;
            for (int p = 0; p < sg.convex[c].nplanes && keep; ++p) {
              const Clip r = clip_half_space(P, sg.convex[c].p[p], eps);
              keep = r != Clip::empty;
              in_face = in_face || r == Clip::in_face;
            }
            if (!keep) continue;
            if (in_face) {  // owned by another cell if one holds the points beside it
              Vec3 c0{0, 0, 0};
              for (int v = 0; v < P.n; ++v) c0 = add(c0, P.p[v]);
              const Vec3 probe = add(scale(c0, 1.0 / P.n), scale(kTieBreak, 1e-6 * std::min(h, sg.box.diagonal())));
              const Vec3 abs_probe = add(probe, origin);
              bool owned = inside(sg, probe, eps);  // another tet of the same hexahedron
              if (!owned) search.for_each(BBox{abs_probe, abs_probe}, 0.0, [&](int64_t s2, const BBox&) {
                if (owned || s2 == s) return;
                other.build(src, s2, origin, false);
                other.build_planes();
                owned = inside(other, probe, eps);
              });
              if (owned) continue;
            }
            for (int f = 1; f + 1 < P.n; ++f) {
              const Vec3 &a = P.p[0], &b = P.p[f], &d = P.p[f + 1];
              const double area = 0.5 * norm(cross(sub(b, a), sub(d, a)));
              if (!(area > 1e-14 * measure)) continue;
              if (!any) {
                sev.build(src, sg);
                src.dofs(s, sdofs);
                std::fill(block, block + ns * nt, 0.0);
                any = true;
              }
              for (int q = 0; q < rule.npts; ++q) {
                const double* l = &rule.bary[3 * q];
                const Vec3 x = add(add(scale(a, l[0]), scale(b, l[1])), scale(d, l[2]));
                if (nt == 1)
                  phi_t[0] = 1.0;
                else
                  te.eval({dot(x, e1), dot(x, e2)}, phi_t);
                sev.eval(x, phi_s);
                la.add_point(rule.weights[q] * area, phi_t, phi_s, ns, block);
              }
            }
          }
        if (!any) return;
        ++intersected;
        la.add_block(sdofs, ns, block);
      });
      result.overlap[t] = la.overlap;
      la.finish(tdofs, measure, dual, lump, Bparts[tid], Dparts[tid]);
    }
  }
  result.pairs_tested = tested;
  result.pairs_intersected = intersected;
  result.collect(Bparts, Dparts, n_src_dofs, n_tgt_dofs, nth);
  return result;
}

}  // namespace vc
