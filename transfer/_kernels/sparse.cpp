// Triplets -> CSR with duplicate summation: a counting sort by row, then each
// row compacted through a marker per column and sorted (rows in parallel).
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

CSR to_csr(const std::vector<Triplets>& parts, int64_t nrows, int64_t ncols, int nthreads) {
  nthreads = std::max(1, nthreads);
  std::vector<int64_t> start(nrows + 1, 0);
  for (const auto& p : parts)
    for (Index r : p.rows) ++start[r + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<Entry> entries(start[nrows]);
  {
    std::vector<int64_t> next(start.begin(), start.end() - 1);
    for (const auto& p : parts)
      for (size_t k = 0; k < p.rows.size(); ++k) entries[next[p.rows[k]]++] = {p.vals[k], p.cols[k]};
  }
  // Each row: duplicates summed in place through a marker per column (linear in the
  // entries), then the distinct columns sorted.
  std::vector<int64_t> unique(nrows + 1, 0);
#pragma omp parallel num_threads(nthreads)
  {
    std::vector<int64_t> marker(ncols, -1);
#pragma omp for schedule(dynamic, 1024)
    for (int64_t r = 0; r < nrows; ++r) {
      Entry* a = entries.data() + start[r];
      Entry* b = entries.data() + start[r + 1];
      Entry* out = a;
      for (Entry* e = a; e < b; ++e) {
        int64_t& m = marker[e->col];  // where in this row the column is, -1 if not yet
        if (m >= 0) {
          a[m].val += e->val;
        } else {
          m = out - a;
          *out++ = *e;
        }
      }
      std::sort(a, out, [](const Entry& x, const Entry& y) { return x.col < y.col; });
      for (Entry* e = a; e < out; ++e) marker[e->col] = -1;
      unique[r + 1] = out - a;
    }
  }
  CSR csr;
  csr.indptr.resize(nrows + 1);
  std::partial_sum(unique.begin(), unique.end(), csr.indptr.begin());
  csr.indices.resize(csr.indptr[nrows]);
  csr.data.resize(csr.indptr[nrows]);
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int64_t r = 0; r < nrows; ++r)
    for (int64_t k = 0; k < unique[r + 1]; ++k) {
      const Entry& e = entries[start[r] + k];
      csr.indices[csr.indptr[r] + k] = e.col;
      csr.data[csr.indptr[r] + k] = e.val;
    }
  return csr;
}

}  // namespace vc
