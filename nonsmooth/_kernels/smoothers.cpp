// Projected Gauss-Seidel sweeps for bound-constrained quadratic programs
// (nonsmooth multigrid smoother, paper section 2.4).
//
// One sweep minimises J(x) = 1/2 x^T A x - b^T x exactly along each coordinate
// in turn, subject to lower <= x <= upper:
//     x_i <- clip((b_i - sum_{j != i} a_ij x_j) / a_ii, lower_i, upper_i).
// Each coordinate step cannot increase J, so the sweep is monotone. With
// lower = upper = 0 on some components and +-inf elsewhere the same sweep is the
// linear Gauss-Seidel smoother of the truncated matrix (rows and columns of the
// fixed components removed). Rows with a non-positive diagonal (a coarse basis
// function truncated away entirely) are left unchanged.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using IndexArray = nb::ndarray<const int32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using ConstVector = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Vector = nb::ndarray<double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

inline void relax(int64_t i, const int32_t* ptr, const int32_t* idx, const double* val, const double* b,
                  const double* lo, const double* up, double* x) {
  double diag = 0.0, r = b[i];
  for (int32_t k = ptr[i]; k < ptr[i + 1]; ++k) {
    const int32_t j = idx[k];
    if (j == i)
      diag += val[k];
    else
      r -= val[k] * x[j];
  }
  if (diag > 0.0) x[i] = std::min(std::max(r / diag, lo[i]), up[i]);
}

// `sweeps` sweeps; order 0: forward, 1: backward, 2: forward then backward.
void projected_gauss_seidel(IndexArray indptr, IndexArray indices, ConstVector data, ConstVector b,
                            ConstVector lower, ConstVector upper, Vector x, int sweeps, int order) {
  const int64_t n = static_cast<int64_t>(x.shape(0));
  if (static_cast<int64_t>(indptr.shape(0)) != n + 1 || static_cast<int64_t>(b.shape(0)) != n ||
      static_cast<int64_t>(lower.shape(0)) != n || static_cast<int64_t>(upper.shape(0)) != n)
    throw std::invalid_argument("projected_gauss_seidel: A, b, lower, upper and x sizes differ");
  if (order < 0 || order > 2) throw std::invalid_argument("projected_gauss_seidel: order must be 0, 1 or 2");
  if (indices.shape(0) != data.shape(0))
    throw std::invalid_argument("projected_gauss_seidel: indices and data sizes differ");
  const int32_t *ptr = indptr.data(), *idx = indices.data();
  const double *val = data.data(), *bb = b.data(), *lo = lower.data(), *up = upper.data();
  double* xx = x.data();
  nb::gil_scoped_release release;
  for (int s = 0; s < sweeps; ++s) {
    if (order != 1)
      for (int64_t i = 0; i < n; ++i) relax(i, ptr, idx, val, bb, lo, up, xx);
    if (order != 0)
      for (int64_t i = n - 1; i >= 0; --i) relax(i, ptr, idx, val, bb, lo, up, xx);
  }
}

}  // namespace

NB_MODULE(_smoothers, m) {
  m.doc() = "Compiled smoothers of the nonsmooth multigrid (projected Gauss-Seidel).";
  m.def("projected_gauss_seidel", &projected_gauss_seidel, "indptr"_a, "indices"_a, "data"_a, "b"_a,
        "lower"_a, "upper"_a, "x"_a.noconvert(), "sweeps"_a = 1, "order"_a = 0,
        "Projected Gauss-Seidel sweeps on CSR A (int32 indices), in place on x.");
}
