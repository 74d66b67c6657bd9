// Row pieces -> CSR with duplicate summation: the pieces (not the entries) sorted by row,
// then each row's entries summed through a marker per column and sorted (rows in parallel);
// the pieces are emptied on the way.
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

void RowPieces::merge_window() {
  const size_t first = window_, end = rows.size();
  if (end - first < 2) {
    window_ = end;
    return;
  }
  // the window's pieces listed per row, rows in the order they first came
  m_rows.clear();
  std::vector<int64_t> head, tail;
  next_.assign(end - first, -1);
  for (size_t q = first; q < end; ++q) {
    const Index r = rows[q];
    if (static_cast<size_t>(r) >= row_slot_.size()) row_slot_.resize(r + 1, -1);
    int32_t& k = row_slot_[r];
    if (k < 0) {
      k = static_cast<int32_t>(m_rows.size());
      m_rows.push_back(r);
      head.push_back(q - first);
      tail.push_back(q - first);
    } else {
      next_[tail[k]] = q - first;
      tail[k] = q - first;
    }
  }
  m_cols.clear();
  m_vals.clear();
  m_starts.assign(1, starts[first]);
  for (size_t k = 0; k < m_rows.size(); ++k) {
    const size_t row_first = m_cols.size();
    for (int64_t q = head[k]; q >= 0; q = next_[q])
      for (int64_t e = starts[first + q]; e < starts[first + q + 1]; ++e) {
        const Index c = cols[e];
        if (static_cast<size_t>(c) >= col_slot_.size()) col_slot_.resize(c + 1, -1);
        int64_t& m = col_slot_[c];
        if (m >= 0) {
          m_vals[m] += vals[e];
        } else {
          m = static_cast<int64_t>(m_cols.size());
          m_cols.push_back(c);
          m_vals.push_back(vals[e]);
        }
      }
    for (size_t e = row_first; e < m_cols.size(); ++e) col_slot_[m_cols[e]] = -1;
    m_starts.push_back(m_starts[0] + static_cast<int64_t>(m_cols.size()));
    row_slot_[m_rows[k]] = -1;
  }
  // the window replaced by its merge
  rows.resize(first);
  rows.insert(rows.end(), m_rows.begin(), m_rows.end());
  starts.resize(first);
  starts.insert(starts.end(), m_starts.begin(), m_starts.end());
  cols.resize(m_starts[0]);
  cols.insert(cols.end(), m_cols.begin(), m_cols.end());
  vals.resize(m_starts[0]);
  vals.insert(vals.end(), m_vals.begin(), m_vals.end());
  window_ = rows.size();
}

namespace {
struct Entry {
  double val;
  Index col;
};
}  // namespace

CSR to_csr(std::vector<RowPieces>& parts, int64_t nrows, int64_t ncols, int nthreads) {
  nthreads = std::max(1, nthreads);
  for (auto& p : parts) p.merge_window();
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
  // the pieces go before the CSR is made, each block of merged rows once copied (peak memory)
  std::vector<Piece>().swap(pieces);
  for (auto& p : parts) p = RowPieces();
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
    std::vector<Entry>().swap(merged[blk]);
  }
  return csr;
}

}  // namespace vc
