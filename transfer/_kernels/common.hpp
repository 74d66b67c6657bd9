// Shared pieces of the transfer kernels: small vector algebra, the local
// (per target element) accumulation of B and D, and sparse assembly.
//
// Assembly is organised per target element (paper eq. 3): every target element
// gathers the pieces of its intersection with the source mesh, integrates
// products of basis functions on them, and emits its local rows of B (target
// dofs x source dofs) and of D (target x target). Rows are global dof ids, so a
// distributed version only has to give each rank its target elements plus the
// source elements that overlap them.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

namespace vc {

using Vec3 = std::array<double, 3>;

inline Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
inline Vec3 scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
inline double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline Vec3 lerp(const Vec3& a, const Vec3& b, double t) {
  return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])};
}

struct BBox {
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  void grow(const Vec3& p) {
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], p[d]);
      hi[d] = std::max(hi[d], p[d]);
    }
  }
  bool overlaps(const BBox& o, double tol) const {
    for (int d = 0; d < 3; ++d)
      if (lo[d] > o.hi[d] + tol || o.lo[d] > hi[d] + tol) return false;
    return true;
  }
  double diagonal() const { return norm(sub(hi, lo)); }
};

// Quadrature rule on a reference simplex: barycentric points (npts x (dim+1)),
// weights summing to 1 (they are multiplied by the simplex measure).
struct SimplexRule {
  int npts = 0;
  int nbary = 0;
  std::vector<double> bary;
  std::vector<double> weights;
};

// Matrix indices: 32 bits (dofs per process < 2^31, checked by the bindings),
// which halves the memory traffic of assembly.
using Index = int32_t;

// Rows of one thread, piece by piece: a piece is the entries one element gives one row
// (its columns and values, in order); merged into CSR by to_csr (sparse.cpp), which
// gathers the pieces of a row instead of sorting every entry by row. The pieces of the
// last kWindow given are merged row by row as they come (merge_window): neighbouring
// elements, which share rows, tend to come close together, so fewer entries are stored.
struct RowPieces {
  static constexpr size_t kWindow = 8192;
  std::vector<Index> rows;       // per piece
  std::vector<int64_t> starts{0};  // per piece: where its entries start; one more at the end
  std::vector<Index> cols;       // per entry
  std::vector<double> vals;
  // Room for `pieces` pieces of `entries` entries in all.
  void reserve(size_t pieces, size_t entries) {
    rows.reserve(pieces);
    starts.reserve(pieces + 1);
    cols.reserve(entries);
    vals.reserve(entries);
  }
  size_t size() const { return rows.size(); }
  // A piece of row r: its entries follow with add, up to the next row().
  void row(int64_t r) {
    if (rows.size() - window_ >= kWindow) merge_window();
    rows.push_back(static_cast<Index>(r));
    starts.push_back(starts.back());
  }
  void add(int64_t c, double v) {
    cols.push_back(static_cast<Index>(c));
    vals.push_back(v);
    ++starts.back();
  }
  // The pieces since the last merge as one piece per row (in the order the rows first
  // came), each entry's values summed in the order given; an entry stays, as in to_csr,
  // when they sum to zero.
  void merge_window();

 private:
  size_t window_ = 0;                   // the first piece not merged
  std::vector<int32_t> row_slot_;       // per row: its piece in the window, -1
  std::vector<int64_t> col_slot_;       // per column: its entry in the row merged, -1
  std::vector<Index> m_rows, m_cols;    // the merged window
  std::vector<int64_t> m_starts, next_;
  std::vector<double> m_vals;
};

struct CSR {
  std::vector<int64_t> indptr;
  std::vector<Index> indices;
  std::vector<double> data;
};

// Sum the row pieces of all threads (their last windows merged first) into a CSR matrix
// with nrows rows and ncols columns (duplicates added in the order of the threads and
// pieces, columns sorted within each row).
// `parts` are left empty (their memory goes before the CSR is made).
CSR to_csr(std::vector<RowPieces>& parts, int64_t nrows, int64_t ncols, int nthreads = 1);

// How a target element enters D (paper eqs. 3-4):
// - covered entirely by the source (relative tolerance kFullCoverage on the
//   measures): its mass matrix as integrated, or with the dual basis of eq. 4;
// - cut by the edge of the overlap: the dual basis is not biorthogonal there,
//   so the standard basis is used. On a small piece of an element the basis
//   functions are nearly linearly dependent and the consistent mass over the
//   overlap nearly singular (their values at the vertices are not determined
//   by the data): where the Jacobi-scaled local mass has a Cholesky pivot below
//   kMinPivot it is lumped, which keeps D positive definite and the integral
//   over the overlap exact.
constexpr double kFullCoverage = 1e-10;
constexpr double kMinPivot = 1e-6;

// Local accumulation for one target element with `nt` basis functions.
// B_loc[s][a] = integral of (source basis of source dof s) * (target basis a);
// M_loc[a][b] = integral over the overlap of target basis a * target basis b.
struct LocalAssembly {
  int nt = 0;
  std::vector<int64_t> src_dofs;          // distinct source dofs seen
  std::vector<double> b;                  // src_dofs.size() x nt
  std::array<double, 64> m{};             // nt x nt (nt <= 8)
  double overlap = 0.0;                   // measure of target element covered
  std::vector<int32_t>* slot = nullptr;   // global source dof -> local slot, -1 if none

  void reset(int nt_, std::vector<int32_t>* slot_) {
    for (int64_t s : src_dofs) (*slot_)[s] = -1;
    nt = nt_;
    slot = slot_;
    src_dofs.clear();
    b.clear();
    m.fill(0.0);
    overlap = 0.0;
  }
  double* row_of(int64_t sdof) {
    int32_t k = (*slot)[sdof];
    if (k < 0) {
      k = static_cast<int32_t>(src_dofs.size());
      (*slot)[sdof] = k;
      src_dofs.push_back(sdof);
      b.resize(b.size() + nt, 0.0);
    }
    return b.data() + static_cast<size_t>(k) * nt;
  }
  // Quadrature point of weight w: block[i * nt + a] += w phi_s[i] phi_t[a] (the
  // B block of one source element, see add_block) and M += w phi_t phi_t^T.
  void add_point(double w, const double* phi_t, const double* phi_s, int ns, double* block) {
    double wt[8];
    for (int a = 0; a < nt; ++a) wt[a] = w * phi_t[a];
    for (int i = 0; i < ns; ++i)
      for (int a = 0; a < nt; ++a) block[i * nt + a] += phi_s[i] * wt[a];
    for (int a = 0; a < nt; ++a)
      for (int c = 0; c < nt; ++c) m[a * nt + c] += wt[a] * phi_t[c];
    overlap += w;
  }
  // Add the block of one source element: vals[i * nt + a] = int phi_s[i] phi_t[a].
  void add_block(const int64_t* sdofs, int ns, const double* vals) {
    for (int i = 0; i < ns; ++i) {
      double* row = row_of(sdofs[i]);
      for (int a = 0; a < nt; ++a) row[a] += vals[i * nt + a];
    }
  }
  // A = diag(M 1) M^{-1} (row-major into `a`) by Gauss-Jordan elimination with
  // partial pivoting; false if M is singular.
  bool dual_coefficients(double* a) const {
    double w[8][16];
    for (int i = 0; i < nt; ++i)
      for (int j = 0; j < nt; ++j) {
        w[i][j] = m[i * nt + j];
        w[i][nt + j] = (i == j) ? 1.0 : 0.0;
      }
    for (int c = 0; c < nt; ++c) {
      int piv = c;
      for (int r = c + 1; r < nt; ++r)
        if (std::fabs(w[r][c]) > std::fabs(w[piv][c])) piv = r;
      if (w[piv][c] == 0.0) return false;
      for (int j = 0; j < 2 * nt; ++j) std::swap(w[c][j], w[piv][j]);
      const double inv = 1.0 / w[c][c];
      for (int j = 0; j < 2 * nt; ++j) w[c][j] *= inv;
      for (int r = 0; r < nt; ++r)
        if (r != c && w[r][c] != 0.0) {
          const double f = w[r][c];
          for (int j = 0; j < 2 * nt; ++j) w[r][j] -= f * w[c][j];
        }
    }
    for (int i = 0; i < nt; ++i) {
      double rowsum = 0.0;
      for (int j = 0; j < nt; ++j) rowsum += m[i * nt + j];
      for (int j = 0; j < nt; ++j) a[i * nt + j] = rowsum * w[i][nt + j];
    }
    return true;
  }
  // Emit the element of measure `measure` by the policy above.
  void finish(const int64_t* tdofs, double measure, bool dual, bool lump, RowPieces& B, RowPieces& D) const {
    const bool full = overlap >= (1.0 - kFullCoverage) * measure;
    emit(tdofs, dual && full, lump || (!full && !well_conditioned()), B, D);
  }

  // Smallest squared Cholesky pivot of the Jacobi-scaled local mass > kMinPivot.
  bool well_conditioned() const {
    double l[8][8];
    for (int i = 0; i < nt; ++i)
      if (!(m[i * nt + i] > 0.0)) return false;
    for (int i = 0; i < nt; ++i)
      for (int j = 0; j <= i; ++j) {
        double v = m[i * nt + j] / std::sqrt(m[i * nt + i] * m[j * nt + j]);
        for (int k = 0; k < j; ++k) v -= l[i][k] * l[j][k];
        if (i == j) {
          if (!(v > kMinPivot)) return false;
          l[i][i] = std::sqrt(v);
        } else {
          l[i][j] = v / l[j][j];
        }
      }
    return true;
  }

  // Emit the local rows into global triplets. `tdofs` are the target element's
  // dofs; with `use_dual` the rows are those of the dual basis (paper eq. 4),
  // psi_a = sum_c A[a][c] phi_c with A = diag(M 1) M^{-1} from the element's
  // own mass matrix M as integrated here, so int psi_a phi_c = delta_ac int phi_c
  // holds for exactly the integration that B uses. `lump` replaces the local
  // mass matrix by its row sums (diagonal D).
  void emit(const int64_t* tdofs, bool use_dual, bool lump, RowPieces& B, RowPieces& D) const {
    std::array<double, 64> md{}, coeffs{};
    const double* dual = (use_dual && dual_coefficients(coeffs.data())) ? coeffs.data() : nullptr;
    const size_t ns = src_dofs.size();
    for (int a = 0; a < nt; ++a) {
      B.row(tdofs[a]);
      for (size_t k = 0; k < ns; ++k) {
        const double* row = b.data() + k * nt;
        double v = row[a];
        if (dual) {
          v = 0.0;
          for (int c = 0; c < nt; ++c) v += dual[a * nt + c] * row[c];
        }
        if (v != 0.0) B.add(src_dofs[k], v);
      }
    }
    for (int a = 0; a < nt; ++a)
      for (int c = 0; c < nt; ++c) {
        double v = m[a * nt + c];
        if (dual) {
          v = 0.0;
          for (int e = 0; e < nt; ++e) v += dual[a * nt + e] * m[e * nt + c];
        }
        md[a * nt + c] = v;
      }
    for (int a = 0; a < nt; ++a) {
      D.row(tdofs[a]);
      if (lump) {
        double s = 0.0;
        for (int c = 0; c < nt; ++c) s += md[a * nt + c];
        D.add(tdofs[a], s);
      } else {
        for (int c = 0; c < nt; ++c)
          if (md[a * nt + c] != 0.0) D.add(tdofs[c], md[a * nt + c]);
      }
    }
  }
};

// Threads of an assembly: `nthreads`, or all OpenMP offers when it is <= 0.
int thread_count(int nthreads);

// Result of one assembly, handed to Python.
struct AssemblyResult {
  explicit AssemblyResult(int64_t ntarget = 0) : overlap(ntarget, 0.0), measure(ntarget, 0.0) {}

  CSR B, D;
  std::vector<double> overlap;   // per target element: measure covered by the source
  std::vector<double> measure;   // per target element: its own measure
  int64_t pairs_tested = 0;
  int64_t pairs_intersected = 0;

  // Merge the per-thread row pieces into B and D.
  void collect(std::vector<RowPieces>& b, std::vector<RowPieces>& d, int64_t n_src_dofs,
               int64_t n_tgt_dofs, int nthreads) {
    B = to_csr(b, n_tgt_dofs, n_src_dofs, nthreads);
    D = to_csr(d, n_tgt_dofs, n_tgt_dofs, nthreads);
  }
};

enum Kind : int { TET = 0, HEX = 1, BOX = 2, TRI = 3, QUAD = 4 };

// A mesh as the kernels see it. Dofs: degree 0 -> the cell index, degree 1 ->
// the vertex index (vertex order of VTK for every kind).
struct ElementSet {
  const double* points = nullptr;  // npoints x 3
  int64_t npoints = 0;
  const int64_t* cells = nullptr;  // ncells x nverts
  int64_t ncells = 0;
  int nverts = 0;
  int kind = TET;
  int degree = 1;
  // Optional: the vertex coordinates cell by cell (ncells x nverts x 3), read in place of
  // points[cells]: one contiguous read per cell where the search visits cells in no order.
  const double* cell_coords = nullptr;
  int nbasis() const { return degree == 0 ? 1 : nverts; }
  Vec3 vertex(int64_t c, int k) const {
    const double* p = cell_coords ? cell_coords + 3 * (c * nverts + k) : points + 3 * cells[c * nverts + k];
    return {p[0], p[1], p[2]};
  }
  // The coordinates cell by cell, for cell_coords.
  std::vector<double> packed_coords() const {
    std::vector<double> out(static_cast<size_t>(ncells) * nverts * 3);
    for (int64_t c = 0; c < ncells; ++c)
      for (int k = 0; k < nverts; ++k) {
        const double* p = points + 3 * cells[c * nverts + k];
        for (int d = 0; d < 3; ++d) out[3 * (c * nverts + k) + d] = p[d];
      }
    return out;
  }
  void dofs(int64_t c, int64_t* out) const {
    if (degree == 0)
      out[0] = c;
    else
      for (int k = 0; k < nverts; ++k) out[k] = cells[c * nverts + k];
  }
};

// Axis-aligned structured grid of boxes (cell id = i + nx * (j + ny * k)),
// giving index-based search when the source is such a grid.
struct GridInfo {
  Vec3 origin{}, spacing{};
  std::array<int64_t, 3> shape{};
};


// How far assemble_volume goes, for benchmarks that split its time: the search for
// candidate pairs, then the rejection tests, the clipping, the integration, and
// everything (the rows of B and D in CSR).
enum Stage : int { kSearch = 1, kReject = 2, kClip = 3, kIntegrate = 4, kAll = 5 };

// The longest vertex distance and the signed volume of each of `ncells` tets (shapes.cpp).
void tet_shapes(const double* points, const int64_t* cells, int64_t ncells, double* longest, double* volume);

// Volume-volume (TET, HEX, BOX) by exact polyhedron clipping.
// `rule` is a rule on the reference tetrahedron (4 barycentric coordinates).
// `dual`: use the dual basis of eq. 4 on the target (fully covered elements).
// `stages` < kAll stops early (Stage): for benchmarks only. `reject` false clips every
// candidate pair, without the separating-plane tests (the same result, slower: tests).
AssemblyResult assemble_volume(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule,
                               bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                               const GridInfo* src_grid, int nthreads, int stages = kAll, bool reject = true);

// Volume-surface: source TET/HEX/BOX cells, target TRI/QUAD surface elements
// inside the volume (the trace of the source on the surface). `rule` is on the
// reference triangle.
AssemblyResult assemble_trace(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule, bool dual,
                              bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs, const GridInfo* src_grid,
                              int nthreads);

// Surface-surface (TRI, QUAD embedded in 3D) by mortar segmentation: pair by
// proximity along the target normal, project on the target element's plane,
// clip, integrate. `rule` is on the reference triangle (3 barycentric coords).
AssemblyResult assemble_surface(const ElementSet& src, const ElementSet& tgt, const SimplexRule& rule,
                                bool dual, bool lump, int64_t n_src_dofs, int64_t n_tgt_dofs,
                                double search_distance, double min_normal_cos, int nthreads);

}  // namespace vc
