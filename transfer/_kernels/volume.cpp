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
    swapped_ = !positive;
    if (swapped_) std::swap(x_[1], x_[2]);
    static constexpr int nb[4][3] = {{1, 3, 2}, {2, 3, 0}, {0, 3, 1}, {1, 2, 0}};
    for (int k = 0; k < 4; ++k)
      for (int j = 0; j < 3; ++j) nb_[k][j] = nb[k][j];
  }

  bool empty() const { return n_ == 0; }

  // Keep the part with n.x - d <= eps; false when nothing is left.
  bool clip(const Plane& pl, double eps) {
    double s[kMax];
    for (int v = 0; v < n_; ++v) s[v] = dot(pl.n, x_[v]) - pl.d;
    return cut(s, eps);
  }

  // clip() on the tet just assigned, in one step: what clip does to a tet depends only on
  // which of its vertices lie outside, so each case is a recipe (TetCut) found once by
  // clip itself; the new vertices are the same, in the same order.
  // s_tet[k]: the distance n.x - d of the tet's vertex k to the plane.
  bool clip_tet(const double s_tet[4], double eps) {
    double s[4] = {s_tet[0], s_tet[swapped_ ? 2 : 1], s_tet[swapped_ ? 1 : 2], s_tet[3]};
    int outside = 0;
    for (int v = 0; v < 4; ++v) outside |= (s[v] > eps) << v;
    if (outside == 0) return true;
    if (outside == 15) {
      n_ = 0;
      return false;
    }
    const TetCut& r = tet_cuts()[outside];
    Vec3 x[TetCut::kMax];
    for (int v = 0; v < r.n; ++v) {
      const int a = r.from[v], b = r.to[v];
      if (b < 0) {
        x[v] = x_[a];
      } else {
        const double sa = s[a] >= -eps ? 0.0 : s[a];  // as clip: a vertex within eps lies on the plane
        x[v] = lerp(x_[a], x_[b], sa / (sa - s[b]));
      }
    }
    n_ = r.n;
    for (int v = 0; v < n_; ++v) {
      x_[v] = x[v];
      for (int k = 0; k < 3; ++k) nb_[v][k] = r.nb[v][k];
    }
    return true;
  }

 private:
  // The tet of assign() cut by a plane with the vertices of bit mask `outside` outside:
  // vertex v of the result is old vertex from[v] (to[v] < 0) or the point on the edge from
  // from[v] (inside) to to[v] (outside); nb as nb_.
  struct TetCut {
    static constexpr int kMax = 6;
    int n = 0;
    int from[kMax], to[kMax], nb[kMax][3];
  };
  static const std::array<TetCut, 16>& tet_cuts() {
    static const std::array<TetCut, 16> cuts = [] {
      std::array<TetCut, 16> out{};
      const Tet ref{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};  // positive: assign keeps its order
      for (int outside = 1; outside < 15; ++outside) {
        Polyhedron p;
        p.assign(ref);
        double s[kMax];
        for (int v = 0; v < 4; ++v) s[v] = outside >> v & 1 ? 1.0 : -1.0;
        p.cut(s, 0.5);  // new vertices at the midpoints of the cut edges
        TetCut& r = out[outside];
        r.n = p.n_;
        for (int v = 0; v < p.n_; ++v) {
          for (int k = 0; k < 3; ++k) r.nb[v][k] = p.nb_[v][k];
          r.to[v] = -1;
          for (int a = 0; a < 4; ++a)
            for (int b = 0; b < 4; ++b) {
              const Vec3 mid = scale(add(ref.v[a], ref.v[b]), 0.5);
              if (a == b && p.x_[v] == ref.v[a]) r.from[v] = a;
              if (a != b && !(outside >> a & 1) && (outside >> b & 1) && p.x_[v] == mid) {
                r.from[v] = a;
                r.to[v] = b;
              }
            }
        }
      }
      return out;
    }();
    return cuts;
  }

  // clip() with the distances s[v] of the vertices to the plane.
  bool cut(double* s, double eps) {
    int out = 0;
    for (int v = 0; v < n_; ++v) out += s[v] > eps;
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

 public:
  // Calls f(a, b, c) for the fan triangles (vertex indices) of every face not holding
  // vertex 0: with vertex 0 they are the tets the polyhedron is cut into.
  template <class F>
  void for_each_fan(F&& f) const {
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
        for (int i = 1; i + 1 < m; ++i) f(face[0], face[i], face[i + 1]);
      }
  }

  // The tets from vertex 0 to the fan triangles.
  template <class F>
  void for_each_tet(F&& f) const {
    for_each_fan([&](int a, int b, int c) { f(Tet{{x_[0], x_[a], x_[b], x_[c]}}); });
  }

  // Adds to `m` the moments of the fan tets whose volume exceeds vmin (the pieces
  // for_each_tet gives, integrated in the frame of vertex 0, then moved back: paper
  // eq. 3 with exact integrals of products of affine bases); false when there is none.
  bool add_moments(double vmin, Moments& m) const {
    Vec3 r[kMax];
    for (int v = 1; v < n_; ++v) r[v] = sub(x_[v], x_[0]);
    double p0 = 0.0, p1[3] = {0, 0, 0}, p2[6] = {0, 0, 0, 0, 0, 0};
    for_each_fan([&](int ia, int ib, int ic) {
      const Vec3 &a = r[ia], &b = r[ib], &c = r[ic];
      const double vol = std::fabs(dot(a, cross(b, c))) / 6.0;  // as tet_volume of the piece
      if (!(vol > vmin)) return;
      const double s[3] = {a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2]};
      p0 += vol;
      const double w = vol / 4.0, q = vol / 20.0;
      for (int i = 0; i < 3; ++i) p1[i] += w * s[i];
      for (int i = 0, k = 0; i < 3; ++i)
        for (int j = i; j < 3; ++j, ++k) p2[k] += q * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]);
    });
    if (!(p0 > 0.0)) return false;
    // int (y + x0) = P1 + P0 x0,  int (y + x0)(y + x0)^T = P2 + x0 P1^T + P1 x0^T + P0 x0 x0^T
    const Vec3& o = x_[0];
    m.m0 += p0;
    for (int i = 0; i < 3; ++i) m.m1[i] += p1[i] + p0 * o[i];
    for (int i = 0, k = 0; i < 3; ++i)
      for (int j = i; j < 3; ++j, ++k) m.m2[i][j] += p2[k] + o[i] * p1[j] + p1[i] * o[j] + p0 * o[i] * o[j];
    return true;
  }

 private:
  int slot(int v, int w) const { return nb_[v][0] == w ? 0 : (nb_[v][1] == w ? 1 : 2); }

  int n_ = 0;
  bool swapped_ = false;  // assign() swapped the tet's vertices 1 and 2 (positive orientation)
  Vec3 x_[kMax];
  int nb_[kMax][3];
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

// Signed distances n.x - d of the source points to the face planes of one target tet
// (coordinates relative to its vertex 0, as ElementGeometry::build gives them), each
// computed once per target: a point is shared by about 20 tets of a tet mesh, so the
// separating-plane test of a pair mostly compares distances already at hand.
class PointDistances {
 public:
  PointDistances() = default;
  explicit PointDistances(int64_t npoints) : near_(npoints) {}
  bool empty() const { return near_.empty(); }
  // The distances of point `i` at `x` to the planes of `c`, the target tagged `tag`.
  const double* of(int64_t i, const double* x, const Vec3& origin, const Convex& c, int64_t tag) {
    Near& p = near_[i];
    if (p.tag != tag) {
      p.tag = tag;
      const Vec3 r{x[0] - origin[0], x[1] - origin[1], x[2] - origin[2]};
      for (int k = 0; k < 4; ++k) {
        const Vec3& n = c.p[k].n;
        p.s[k] = n[0] * r[0] + n[1] * r[1] + n[2] * r[2] - c.p[k].d;
      }
    }
    return p.s;
  }

 private:
  struct Near {
    int64_t tag = -1;
    double s[4];
  };
  std::vector<Near> near_;
};

// True when the four points with distances s[k][p] to the planes p of a tet all lie
// outside one plane by more than eps; `cuts` as outside_a_plane gives it.
bool outside_a_plane(const double* const s[4], double eps, unsigned& cuts) {
  int separated = 0;
  cuts = 0;
  for (int p = 0; p < 4; ++p) {
    const int out0 = s[0][p] > eps, out1 = s[1][p] > eps, out2 = s[2][p] > eps, out3 = s[3][p] > eps;
    separated |= out0 & out1 & out2 & out3;
    cuts |= static_cast<unsigned>(out0 | out1 | out2 | out3) << p;
  }
  return separated;
}

// True when every vertex of the `ntets` tets lies outside one plane of `c` by more than
// eps (a separating plane: nothing of them meets `c`); bit p of `cuts` is set when some
// vertex lies outside plane p by more than eps (no bit: all lie inside `c`, and a plane
// without its bit leaves them whole). All planes and vertices are evaluated, without
// branches.
bool outside_a_plane(const Convex& c, const Tet* tets, int ntets, double eps, unsigned& cuts) {
  int separated = 0;
  cuts = 0;
  for (int p = 0; p < c.nplanes; ++p) {
    const Vec3& n = c.p[p].n;
    int out = 1, some = 0;
    for (int t = 0; t < ntets; ++t)
      for (int k = 0; k < 4; ++k) {
        const Vec3& x = tets[t].v[k];
        const double s = n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - c.p[p].d;
        out &= s > eps;
        some |= s > eps;
      }
    separated |= out;
    cuts |= static_cast<unsigned>(some) << p;
  }
  return separated;
}

// What a source tet needs in every candidate pair, computed once per cell instead of once
// per pair: its outward face planes relative to its vertex 0, the diagonal of its box, and
// its affine basis phi_a = c_a + g_a.x (paper eq. 3) with the shape number h max |g_a|.
class SourceTets {
 public:
  SourceTets() = default;
  explicit SourceTets(const ElementSet& e) : cells_(e.ncells), nbasis_(e.nbasis()) {
    ElementGeometry g;
    Evaluator ev;
    double c[4];
    for (int64_t k = 0; k < e.ncells; ++k) {
      Cell& out = cells_[k];
      g.build(e, k, e.vertex(k, 0), false);
      const Convex planes = tet_planes(g.tets[0]);
      for (int i = 0; i < 4; ++i) out.faces[i] = planes.p[i];
      ev.build(e, g);
      ev.affine(c, out.grad);
      out.diagonal = g.box.diagonal();
      out.shape = shape(out.grad, nbasis_, out.diagonal);
    }
  }
  bool empty() const { return cells_.empty(); }
  double diagonal(int64_t k) const { return cells_[k].diagonal; }
  double shape_number(int64_t k) const { return cells_[k].shape; }
  // The faces of cell k in a frame where its vertex 0 is at v0.
  Convex faces(int64_t k, const Vec3& v0) const {
    Convex out;
    out.nplanes = 4;
    for (int i = 0; i < 4; ++i) {
      const Plane& f = cells_[k].faces[i];
      out.p[i] = {f.n, f.d + dot(f.n, v0)};
    }
    return out;
  }
  // outside_a_plane(faces(k, v0), &other, 1, eps, cuts), without the copy of the faces.
  bool separates(int64_t k, const Vec3& v0, const Tet& other, double eps, unsigned& cuts) const {
    int separated = 0;
    cuts = 0;
    for (int i = 0; i < 4; ++i) {
      const Plane& f = cells_[k].faces[i];
      const Vec3& n = f.n;
      const double d = f.d + dot(n, v0);
      int out = 1, some = 0;
      for (const Vec3& x : other.v) {
        const int o = n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - d > eps;
        out &= o;
        some |= o;
      }
      separated |= out;
      cuts |= static_cast<unsigned>(some) << i;
    }
    return separated;
  }
  // The basis of cell k in that frame, as Evaluator::affine gives it.
  void affine(int64_t k, const Vec3& v0, double* c, Vec3* g) const {
    const Vec3* grad = cells_[k].grad;
    c[0] = 1.0;
    g[0] = grad[0];
    for (int i = 1; i < nbasis_; ++i) {
      g[i] = grad[i];
      c[i] = -dot(grad[i], v0);
      c[0] -= c[i];
    }
  }

 private:
  struct Cell {
    std::array<Plane, 4> faces;
    Vec3 grad[4];
    double diagonal, shape;
  };
  std::vector<Cell> cells_;
  int nbasis_ = 0;
};

// The number of planes in a mask of the (at most 6) planes of a Convex; without -mpopcnt
// __builtin_popcount is a library call.
inline int plane_count(unsigned mask) {
  return (mask & 1) + (mask >> 1 & 1) + (mask >> 2 & 1) + (mask >> 3 & 1) + (mask >> 4 & 1) + (mask >> 5 & 1);
}

// The tet t clipped by the planes of `c` with a bit in `cuts` (fed to poly).
// The planes go in the order of how many vertices of t lie outside them, most first: the
// piece shrinks soonest.
inline void clip_tet(const Tet& t, const Convex& c, unsigned cuts, double eps, Polyhedron& poly) {
  poly.assign(t);
  double s[6][4];  // s[p][k]: the distance of vertex k to plane p
  int planes[6], outside[6], m = 0;
  for (int p = 0; p < c.nplanes; ++p) {
    if (!(cuts >> p & 1u)) continue;
    int out = 0;
    for (int k = 0; k < 4; ++k) {
      s[p][k] = dot(c.p[p].n, t.v[k]) - c.p[p].d;
      out += s[p][k] > eps;
    }
    int i = m++;
    for (; i > 0 && outside[i - 1] < out; --i) {
      planes[i] = planes[i - 1];
      outside[i] = outside[i - 1];
    }
    planes[i] = p;
    outside[i] = out;
  }
  for (int i = 0; i < m; ++i)
    if (!(i == 0 ? poly.clip_tet(s[planes[i]], eps) : poly.clip(c.p[planes[i]], eps))) return;
}

// Clips each of the `nsubject` tets of `subject` by convex `c` and hands every
// non-empty piece to piece(poly). With `reject`, a plane of `c` that all subject
// vertices lie outside of rejects the pair, and when `c` holds the planes of the tet
// `other`, a subject tet t whose own faces leave all of `other` outside,
// separated(t, faces_cut), is skipped (both by more than eps): such pairs are those
// clipping finds empty; a plane no subject vertex lies outside of is not clipped by, and
// with `either_way` (an integration exact on any cut of the intersection into tets), when
// fewer of t's faces, faces(t), than planes of `c` cut `other`, `other` is clipped by them
// instead (the same intersection, fewer cuts). Without `reject` every pair is clipped
// by every plane (tests). With `clip` false nothing is clipped (benchmarks: the rejection
// tests alone). `known_cuts`, when given, is the first test's `cuts`, already found
// without a separating plane.
template <class Separated, class Faces, class F>
void clip_convex(const Tet* subject, int nsubject, Separated&& separated, Faces&& faces, const Convex& c,
                 const Tet* other, double eps, bool reject, bool clip, bool either_way, Polyhedron& poly,
                 F&& piece, const unsigned* known_cuts = nullptr) {
  unsigned cuts = ~0u;  // the planes of `c` that cut the subject (all without `reject`)
  if (known_cuts)
    cuts = *known_cuts;
  else if (reject && outside_a_plane(c, subject, nsubject, eps, cuts))
    return;
  for (int t = 0; t < nsubject; ++t) {
    unsigned faces_cut = ~0u;  // the faces of subject tet t that cut `other`
    if (reject && cuts && other && separated(t, faces_cut)) continue;
    if (!clip) continue;
    if (either_way && reject && other && plane_count(faces_cut) < plane_count(cuts))
      clip_tet(*other, faces(t), faces_cut, eps, poly);
    else
      clip_tet(subject[t], c, cuts, eps, poly);
    if (!poly.empty()) piece(poly);
  }
}

}  // namespace

AssemblyResult assemble_volume(const ElementSet& src_in, const ElementSet& tgt, const SimplexRule& rule,
                               bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                               const GridInfo* src_grid, int nthreads, int stages, bool reject) {
  AssemblyResult result(tgt.ncells);
  const int nth = thread_count(nthreads);
  std::vector<RowPieces> Bparts(nth), Dparts(nth);
  int64_t tested = 0, intersected = 0;
  {  // the search structures go before the rows are merged (peak memory)
    ElementSet src = src_in;
    const bool tet_pairs = src.kind == TET && tgt.kind == TET;
    // Source vertices cell by cell: one read per candidate where the search visits cells in no
    // order; tet-tet pairs with rejection read the points through PointDistances instead.
    std::vector<double> coords;
    if (!(tet_pairs && reject)) {
      coords = src.packed_coords();
      src.cell_coords = coords.data();
    }
    const SourceSearch search(src, src_grid);
    const SourceTets src_tets = tet_pairs ? SourceTets(src) : SourceTets();
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
      // about 14 source dofs per target cell of P1 tet pairs of similar size: room for 16
      const size_t cells = tgt.ncells / nth + 1;
      Bparts[tid].reserve(nt * cells, 16 * nt * cells);
      Dparts[tid].reserve(nt * cells, (lump ? 1 : nt) * nt * cells);
      // tet-tet pairs: the first separating-plane test from distances of the source points
      PointDistances near = reject && !src_tets.empty() ? PointDistances(src.npoints) : PointDistances();
      LocalAssembly la;
      Polyhedron poly;
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
        search.for_each(search_box, 1e-10 * h, [&](int64_t s, const BBox& b) {
          ++tested;
          if (stages < kReject) return;
          // the tolerance of the pair's tests and clipping, from the smaller of the two elements
          auto tolerance = [&](double diagonal) { return 1e-12 * std::min(h, diagonal) + 4 * DBL_EPSILON * h; };
          double eps = src_tets.empty() ? 0.0 : tolerance(src_tets.diagonal(s));
          unsigned cuts = 0;
          if (!near.empty()) {  // source points outside a target plane
            const int64_t* v = src.cells + 4 * s;
            const double* d[4];
            for (int k = 0; k < 4; ++k) d[k] = near.of(v[k], src.points + 3 * v[k], origin, tg.convex[0], t);
            if (outside_a_plane(d, eps, cuts)) return;
          } else if (reject && tg.nconvex == 1) {
            if (box_outside(sub(b.lo, origin), sub(b.hi, origin), tg.convex[0], eps_box)) return;
          }
          sg.build(src, s, origin, false);
          if (src_tets.empty()) eps = tolerance(sg.box.diagonal());
          // Clip the tets of the element with fewer of them by the convex pieces
          // of the other (fewest tet-piece pairs).
          const bool clip_source = sg.ntets * tg.convex_count() <= tg.ntets * sg.convex_count();
          const ElementGeometry& subj = clip_source ? sg : tg;
          ElementGeometry& clipper = clip_source ? tg : sg;
          clipper.build_planes();
          // a subject tet whose faces leave a tet clipper outside (the faces of a source tet
          // are computed once, those of other tets here)
          const Tet* other = clipper.kind == TET ? &clipper.tets[0] : nullptr;  // its faces separate too
          const bool source_faces = clip_source && !src_tets.empty();  // computed once per source tet
          auto faces = [&](int k) { return source_faces ? src_tets.faces(s, sg.verts[0]) : tet_planes(subj.tets[k]); };
          auto separated = [&](int k, unsigned& faces_cut) {
            if (source_faces) return src_tets.separates(s, sg.verts[0], *other, eps, faces_cut);
            return outside_a_plane(faces(k), other, 1, eps, faces_cut);
          };
          bool prepared = false, any = false, moments = false;
          const SimplexRule* q_rule = &rule;
          auto integrate = [&](const Polyhedron& poly) {
            if (stages < kIntegrate) return;
            if (!prepared) {
              src.dofs(s, sdofs);
              std::fill(block, block + ns * nt, 0.0);
              if (exact && !src_tets.empty()) {
                src_tets.affine(s, sg.verts[0], cs, gs);
                moments = moments_t && src_tets.shape_number(s) <= kSliverShape;
              } else if (exact) {
                sev.build(src, sg);
                sev.affine(cs, gs);
                moments = moments_t && shape(gs, ns, sg.box.diagonal()) <= kSliverShape;
              }
              if (exact && !moments) q_rule = &kDegree2;
              if (!moments) sev.build(src, sg);
              pair = Moments{};
              prepared = true;
            }
            if (moments) {
              any = poly.add_moments(vmin, pair) || any;
              return;
            }
            poly.for_each_tet([&](const Tet& piece) {
              const double vol = tet_volume(piece);
              if (!(vol > vmin)) return;
              any = true;
              for (int q = 0; q < q_rule->npts; ++q) {
                const double* l = &q_rule->bary[4 * q];
                Vec3 x{0, 0, 0};
                for (int k = 0; k < 4; ++k) x = add(x, scale(piece.v[k], l[k]));
                tev.eval(x, phi_t);
                sev.eval(x, phi_s);
                la.add_point(q_rule->weights[q] * vol, phi_t, phi_s, ns, block);
              }
            });
          };
          for (int c = 0; c < clipper.nconvex; ++c)
            clip_convex(subj.tets, subj.ntets, separated, faces, clipper.convex[c], other, eps, reject,
                        stages >= kClip, exact && tet_pairs, poly, integrate, near.empty() ? nullptr : &cuts);
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
        if (stages >= kAll) la.finish(tdofs, tg.measure, dual, lump, Bparts[tid], Dparts[tid]);
      }
    }
  }
  result.pairs_tested = tested;
  result.pairs_intersected = intersected;
  result.collect(Bparts, Dparts, n_src_dofs, n_tgt_dofs, nth);
  return result;
}

}  // namespace vc
