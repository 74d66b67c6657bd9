// The size and orientation of tetrahedra in one pass (mesh validation): the longest
// distance between two vertices of each cell and its signed volume, with the operations of
// transfer/mesh.py's numpy versions in the same order (the same values, bit for bit).
#include <algorithm>
#include <cmath>

#include "common.hpp"

namespace vc {

void tet_shapes(const double* points, const int64_t* cells, int64_t ncells, double* longest, double* volume) {
  static constexpr int kEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  for (int64_t c = 0; c < ncells; ++c) {
    const double* p[4];
    for (int k = 0; k < 4; ++k) p[k] = points + 3 * cells[4 * c + k];
    double h = 0.0;
    for (const auto& e : kEdges) {
      const double d0 = p[e[0]][0] - p[e[1]][0], d1 = p[e[0]][1] - p[e[1]][1], d2 = p[e[0]][2] - p[e[1]][2];
      double squared = d0 * d0 + d1 * d1;
      squared += d2 * d2;
      h = std::max(h, squared);
    }
    longest[c] = std::sqrt(h);
    const double a0 = p[1][0] - p[0][0], a1 = p[1][1] - p[0][1], a2 = p[1][2] - p[0][2];
    const double b0 = p[2][0] - p[0][0], b1 = p[2][1] - p[0][1], b2 = p[2][2] - p[0][2];
    const double c0 = p[3][0] - p[0][0], c1 = p[3][1] - p[0][1], c2 = p[3][2] - p[0][2];
    volume[c] = (a0 * (b1 * c2 - b2 * c1) + a1 * (b2 * c0 - b0 * c2) + a2 * (b0 * c1 - b1 * c0)) / 6.0;
  }
}

}  // namespace vc
