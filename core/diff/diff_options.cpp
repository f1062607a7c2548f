#include "core/diff/diff_options.h"

#include <stdexcept>
#include "core/diff/terms/seeding.h"
#include "core/guiding/grid.h"

namespace limn {

void validate_diff_options(const Scene& scene, const DiffParams& params, const DiffOptions& opt) {
  if (params.empty()) throw std::invalid_argument(scene.source + ": no differentiable parameters (call set_differentiable first)");
  if (opt.boundary_sampler != "independent" && opt.boundary_sampler != "stratified")
    throw std::invalid_argument(scene.source + ": boundary_sampler must be 'independent' or 'stratified' (got '" + opt.boundary_sampler + "')");
  if (opt.guiding != "none" && opt.guiding != "grid" && opt.guiding != "octree")
    throw std::invalid_argument(scene.source + ": guiding must be 'none', 'grid' or 'octree' (got '" + opt.guiding + "')");
  parse_seed_segments(opt.project_seed, scene.source);
  if (!(opt.octree_grid_mix >= 0.0f && opt.octree_grid_mix < 1.0f))
    throw std::invalid_argument(scene.source + ": octree_grid_mix must be in [0, 1) (got " + std::to_string(opt.octree_grid_mix) + ")");
  if (!(opt.direction_mix >= 0.0f && opt.direction_mix < 1.0f))
    throw std::invalid_argument(scene.source + ": direction_mix must be in [0, 1) (got " + std::to_string(opt.direction_mix) + ")");
  if (opt.direction_octaves < 0 || opt.direction_octaves > 8)
    throw std::invalid_argument(scene.source + ": direction_octaves must be in [0, 8] (got " + std::to_string(opt.direction_octaves) + ")");
  if (opt.direction_resolution < 1 || opt.direction_resolution > BoundaryGrid::kMaxResolution)
    throw std::invalid_argument(scene.source + ": direction_resolution must be in [1, " + std::to_string(BoundaryGrid::kMaxResolution) +
                                "] (got " + std::to_string(opt.direction_resolution) + ")");
  const std::array<int, 3> cells = grid_cells(opt);
  if (opt.guiding != "none" && (opt.grid_resolution < 1 || size_t(cells[0]) * cells[1] * cells[2] > BoundaryGrid::kMaxCells))
    throw std::invalid_argument(scene.source + ": grid_resolution " + std::to_string(opt.grid_resolution) + " gives " +
                                std::to_string(size_t(cells[0]) * cells[1] * cells[2]) + " grid cells, which exceed the limit of " +
                                std::to_string(BoundaryGrid::kMaxCells));
  if (opt.grid_octaves < 0 || opt.grid_octaves > 8)
    throw std::invalid_argument(scene.source + ": grid_octaves must be in [0, 8] (got " + std::to_string(opt.grid_octaves) + ")");
  if (opt.octree_training < 0)
    throw std::invalid_argument(scene.source + ": octree_training must be >= 0 (got " + std::to_string(opt.octree_training) + ")");
  if (opt.guiding_spp < 1 || opt.guiding_seeds < 0)
    throw std::invalid_argument(scene.source + ": guiding_spp must be >= 1 and guiding_seeds >= 0 (0: the guide's default)");
  if (opt.spp_boundary < 0 || opt.spp_primary < 0 || opt.spp_interior < -1)
    throw std::invalid_argument(scene.source + ": sample counts must be >= 0 (spp_interior also -1: the scene's)");
}

}  // namespace limn
