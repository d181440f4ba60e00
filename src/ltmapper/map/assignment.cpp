// Least-cost assignment (the Hungarian method with row and column potentials, O(n^2 m)) for
// LinkMoved: the few objects one step removed and added.
#include "ltmapper/map/detail.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ltm::map::detail {
namespace {

// Rows 1..n to distinct columns 1..m (n <= m) at the least total of a[i][j] (1-based, all finite).
// Returns each row's column. Each row enters in turn; the shortest augmenting path from it over
// reduced costs a - u - v reaches a free column, and the potentials keep every reduced cost >= 0.
std::vector<std::size_t> Hungarian(const std::vector<std::vector<double>>& a, std::size_t n, std::size_t m) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u(n + 1, 0.0), v(m + 1, 0.0);
  std::vector<std::size_t> row_of(m + 1, 0), way(m + 1, 0);  // column 0: the row entering
  for (std::size_t i = 1; i <= n; ++i) {
    row_of[0] = i;
    std::size_t j0 = 0;
    std::vector<double> reach(m + 1, inf);
    std::vector<char> used(m + 1, 0);
    do {
      used[j0] = 1;
      const std::size_t i0 = row_of[j0];
      double delta = inf;
      std::size_t j1 = 0;
      for (std::size_t j = 1; j <= m; ++j) {
        if (used[j]) continue;
        const double cur = a[i0][j] - u[i0] - v[j];
        if (cur < reach[j]) reach[j] = cur, way[j] = j0;
        if (reach[j] < delta) delta = reach[j], j1 = j;
      }
      for (std::size_t j = 0; j <= m; ++j) {
        if (used[j]) u[row_of[j]] += delta, v[j] -= delta;
        else reach[j] -= delta;
      }
      j0 = j1;
    } while (row_of[j0] != 0);
    do {  // flip the path's pairs back to the entering row
      const std::size_t j1 = way[j0];
      row_of[j0] = row_of[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<std::size_t> col_of(n + 1, 0);
  for (std::size_t j = 1; j <= m; ++j) col_of[row_of[j]] = j;
  return col_of;
}

}  // namespace

std::vector<std::pair<std::size_t, std::size_t>> LeastCostPairs(const std::vector<std::vector<double>>& cost) {
  const std::size_t rows = cost.size(), cols = rows ? cost[0].size() : 0;
  double total = 0.0;  // a forbidden pair costs more than every allowed one together
  for (const auto& r : cost)
    for (const double c : r)
      if (std::isfinite(c)) total += c;
  const double forbidden = 2.0 * total + 1.0;
  const bool flip = rows > cols;  // Hungarian wants rows <= columns
  const std::size_t n = flip ? cols : rows, m = flip ? rows : cols;
  std::vector<std::vector<double>> a(n + 1, std::vector<double>(m + 1, 0.0));
  for (std::size_t i = 0; i < rows; ++i)
    for (std::size_t j = 0; j < cols; ++j) {
      const double c = std::isfinite(cost[i][j]) ? cost[i][j] : forbidden;
      (flip ? a[j + 1][i + 1] : a[i + 1][j + 1]) = c;
    }
  const std::vector<std::size_t> col_of = Hungarian(a, n, m);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t k = 1; k <= n; ++k) {
    const std::size_t i = flip ? col_of[k] - 1 : k - 1, j = flip ? k - 1 : col_of[k] - 1;
    if (std::isfinite(cost[i][j])) pairs.emplace_back(i, j);
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

}  // namespace ltm::map::detail
