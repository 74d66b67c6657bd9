// Python bindings of the transfer kernels (nanobind). Arrays are taken
// without copies where their layout allows; results are returned as numpy
// arrays owned by Python.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/array.h>

#include <climits>
#include <tuple>
#include <optional>
#include <stdexcept>
#include <string>

#include "common.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using Points = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Cells = nb::ndarray<const int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Vector = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Grid = std::tuple<std::array<double, 3>, std::array<double, 3>, std::array<int64_t, 3>>;

template <class T>
nb::ndarray<nb::numpy, T, nb::ndim<1>> to_numpy(std::vector<T>&& v) {
  auto* heap = new std::vector<T>(std::move(v));
  nb::capsule owner(heap, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
  return nb::ndarray<nb::numpy, T, nb::ndim<1>>(heap->data(), {heap->size()}, owner);
}

void check_dofs(int64_t n_src_dofs, int64_t n_tgt_dofs) {
  if (n_src_dofs > INT32_MAX || n_tgt_dofs > INT32_MAX)
    throw std::invalid_argument("more than 2^31 dofs in one process: partition the meshes");
}

vc::ElementSet element_set(const Points& pts, const Cells& cells, int kind, int degree) {
  if (pts.shape(1) != 3) throw std::invalid_argument("points must have shape (n, 3)");
  vc::ElementSet e;
  e.points = pts.data();
  e.npoints = static_cast<int64_t>(pts.shape(0));
  e.cells = cells.data();
  e.ncells = static_cast<int64_t>(cells.shape(0));
  e.nverts = static_cast<int>(cells.shape(1));
  e.kind = kind;
  e.degree = degree;
  if (degree != 0 && degree != 1) throw std::invalid_argument("degree must be 0 or 1");
  return e;
}

vc::SimplexRule simplex_rule(const Points& bary, const Vector& w) {
  vc::SimplexRule r;
  r.npts = static_cast<int>(bary.shape(0));
  r.nbary = static_cast<int>(bary.shape(1));
  r.bary.assign(bary.data(), bary.data() + bary.size());
  r.weights.assign(w.data(), w.data() + w.size());
  if (static_cast<int>(w.shape(0)) != r.npts) throw std::invalid_argument("rule: weights and points differ");
  return r;
}

nb::dict to_dict(vc::AssemblyResult&& r) {
  nb::dict d;
  d["B"] = nb::make_tuple(to_numpy(std::move(r.B.indptr)), to_numpy(std::move(r.B.indices)),
                          to_numpy(std::move(r.B.data)));
  d["D"] = nb::make_tuple(to_numpy(std::move(r.D.indptr)), to_numpy(std::move(r.D.indices)),
                          to_numpy(std::move(r.D.data)));
  d["overlap"] = to_numpy(std::move(r.overlap));
  d["measure"] = to_numpy(std::move(r.measure));
  d["pairs_tested"] = r.pairs_tested;
  d["pairs_intersected"] = r.pairs_intersected;
  return d;
}

}  // namespace

NB_MODULE(_kernels, m) {
  m.doc() = "Compiled kernels of varcouple.transfer: search, clipping, quadrature, sparse assembly";
  // Volume-like kernels: a volume source (mesh or grid); `stages` < 5 stops the volume
  // kernel after the search (1), the rejection tests (2), the clipping (3) or the
  // integration (4) (vc::Stage), so that benchmarks see where the time goes; `reject`
  // false clips every candidate pair without the separating-plane tests (tests compare).
  auto volume_like = [](auto kernel, int nbary, const char* name) {
    return [kernel, nbary, name](const Points& sp, const Cells& sc, int skind, int sdeg, const Points& tp,
                                 const Cells& tc, int tkind, int tdeg, const Points& bary, const Vector& w, bool dual,
                                 bool lump, int64_t nsd, int64_t ntd, std::optional<Grid> grid, int nthreads,
                                 int stages, bool reject) {
      check_dofs(nsd, ntd);
      auto src = element_set(sp, sc, skind, sdeg);
      auto tgt = element_set(tp, tc, tkind, tdeg);
      auto rule = simplex_rule(bary, w);
      if (rule.nbary != nbary)
        throw std::invalid_argument(std::string(name) + ": the rule needs " + std::to_string(nbary) +
                                    " barycentric coordinates");
      vc::GridInfo g;
      if (grid) {
        g.origin = std::get<0>(*grid);
        g.spacing = std::get<1>(*grid);
        g.shape = std::get<2>(*grid);
      }
      vc::AssemblyResult r;
      {
        nb::gil_scoped_release release;
        r = kernel(src, tgt, rule, dual, lump, nsd, ntd, grid ? &g : nullptr, nthreads, stages, reject);
      }
      return to_dict(std::move(r));
    };
  };
  auto trace = [](const vc::ElementSet& src, const vc::ElementSet& tgt, const vc::SimplexRule& rule, bool dual,
                  bool lump, int64_t nsd, int64_t ntd, const vc::GridInfo* grid, int nthreads, int stages,
                  bool reject) {
    if (stages != vc::kAll || !reject) throw std::invalid_argument("assemble_trace: stages must be 5, reject true");
    return vc::assemble_trace(src, tgt, rule, dual, lump, nsd, ntd, grid, nthreads);
  };
  auto args = std::make_tuple("src_points"_a, "src_cells"_a, "src_kind"_a, "src_degree"_a, "tgt_points"_a,
                              "tgt_cells"_a, "tgt_kind"_a, "tgt_degree"_a, "rule_points"_a, "rule_weights"_a,
                              "dual"_a, "lump"_a, "n_src_dofs"_a, "n_tgt_dofs"_a, "grid"_a.none(), "nthreads"_a = 1,
                              "stages"_a = static_cast<int>(vc::kAll), "reject"_a = true);
  std::apply([&](auto... a) { m.def("assemble_volume", volume_like(&vc::assemble_volume, 4, "assemble_volume"), a...); },
             args);
  std::apply([&](auto... a) { m.def("assemble_trace", volume_like(trace, 3, "assemble_trace"), a...); }, args);
  m.def(
      "assemble_surface",
      [](const Points& sp, const Cells& sc, int skind, int sdeg, const Points& tp, const Cells& tc, int tkind,
         int tdeg, const Points& bary, const Vector& w, bool dual, bool lump, int64_t nsd,
         int64_t ntd, double search_distance, double min_normal_cos, int nthreads) {
        check_dofs(nsd, ntd);
        auto src = element_set(sp, sc, skind, sdeg);
        auto tgt = element_set(tp, tc, tkind, tdeg);
        auto rule = simplex_rule(bary, w);
        if (rule.nbary != 3) throw std::invalid_argument("surface rule needs 3 barycentric coordinates");
        vc::AssemblyResult r;
        {
          nb::gil_scoped_release release;
          r = vc::assemble_surface(src, tgt, rule, dual, lump, nsd, ntd, search_distance, min_normal_cos,
                                   nthreads);
        }
        return to_dict(std::move(r));
      },
      "src_points"_a, "src_cells"_a, "src_kind"_a, "src_degree"_a, "tgt_points"_a, "tgt_cells"_a,
      "tgt_kind"_a, "tgt_degree"_a, "rule_points"_a, "rule_weights"_a, "dual"_a, "lump"_a,
      "n_src_dofs"_a, "n_tgt_dofs"_a, "search_distance"_a, "min_normal_cos"_a, "nthreads"_a = 1);
  m.def(
      "tet_shapes",
      [](const Points& pts, const Cells& cells) {
        if (pts.shape(1) != 3 || cells.shape(1) != 4) throw std::invalid_argument("tet_shapes: points (n, 3), cells (m, 4)");
        const size_t n = cells.shape(0);
        std::vector<double> longest(n), volume(n);
        vc::tet_shapes(pts.data(), cells.data(), static_cast<int64_t>(n), longest.data(), volume.data());
        return nb::make_tuple(to_numpy(std::move(longest)), to_numpy(std::move(volume)));
      },
      "points"_a, "cells"_a,
      "(longest vertex distance, signed volume) of each tet; cell vertex indices must be in range");
  m.attr("TET") = static_cast<int>(vc::TET);
  m.attr("HEX") = static_cast<int>(vc::HEX);
  m.attr("BOX") = static_cast<int>(vc::BOX);
  m.attr("TRI") = static_cast<int>(vc::TRI);
  m.attr("QUAD") = static_cast<int>(vc::QUAD);
}
