// Row pieces -> CSR with duplicate summation: the pieces (not the entries) sorted by row,
// then each row's entries summed through a marker per column and sorted (rows in parallel).
#include <algorithm>
#include <numeric>

#include "common.hpp"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace vc {

int thread_count(int nthreads) {
#ifdef _OPENMP
  return nthreads > 0 ? nthreads : omp_get_max_threads();
#else
  (void)nthreads;
  return 1;
#endif
}

namespace {
struct Entry {
  double val;
  Index col;
};
}  // namespace

CSR to_csr(const std::vector<RowPieces>& parts, int64_t nrows, int64_t ncols, int nthreads) {
  nthreads = std::max(1, nthreads);
  // the pieces of each row, in the order of the parts: a counting sort of the pieces by row
  struct Piece {
    const RowPieces* part;
    size_t k;
  };
  std::vector<int64_t> start(nrows + 1, 0);
  for (const auto& p : parts)
    for (Index r : p.rows) ++start[r + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<Piece> pieces(start[nrows]);
  {
    std::vector<int64_t> next(start.begin(), start.end() - 1);
    for (const auto& p : parts)
      for (size_t k = 0; k < p.size(); ++k) pieces[next[p.rows[k]]++] = {&p, k};
  }
  // Each row: its pieces' entries summed through a marker per column (linear in the
  // entries), the distinct columns sorted; rows in blocks, one block's rows per thread.
  const int64_t nblocks = std::max<int64_t>(1, std::min<int64_t>(4 * nthreads, nrows));
  std::vector<std::vector<Entry>> merged(nblocks);
  std::vector<int64_t> unique(nrows + 1, 0);
#pragma omp parallel num_threads(nthreads)
  {
    std::vector<int64_t> marker(ncols, -1);
#pragma omp for schedule(dynamic, 1)
    for (int64_t blk = 0; blk < nblocks; ++blk) {
      std::vector<Entry>& out = merged[blk];
      for (int64_t r = nrows * blk / nblocks; r < nrows * (blk + 1) / nblocks; ++r) {
        const size_t first = out.size();
        for (int64_t q = start[r]; q < start[r + 1]; ++q) {
          const RowPieces& p = *pieces[q].part;
          const size_t k = pieces[q].k;
          for (int64_t e = p.starts[k]; e < p.starts[k + 1]; ++e) {
            int64_t& m = marker[p.cols[e]];  // where in `out` the column is, -1 if not yet
            if (m >= 0) {
              out[m].val += p.vals[e];
            } else {
              m = static_cast<int64_t>(out.size());
              out.push_back({p.vals[e], p.cols[e]});
            }
          }
        }
        std::sort(out.begin() + first, out.end(), [](const Entry& x, const Entry& y) { return x.col < y.col; });
        for (size_t e = first; e < out.size(); ++e) marker[out[e].col] = -1;
        unique[r + 1] = static_cast<int64_t>(out.size() - first);
      }
    }
  }
  CSR csr;
  csr.indptr.resize(nrows + 1);
  std::partial_sum(unique.begin(), unique.end(), csr.indptr.begin());
  csr.indices.resize(csr.indptr[nrows]);
  csr.data.resize(csr.indptr[nrows]);
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int64_t blk = 0; blk < nblocks; ++blk) {
    const int64_t offset = csr.indptr[nrows * blk / nblocks];
    for (size_t e = 0; e < merged[blk].size(); ++e) {
      csr.indices[offset + e] = merged[blk][e].col;
      csr.data[offset + e] = merged[blk][e].val;
    }
  }
  return csr;
}

}  // namespace vc
