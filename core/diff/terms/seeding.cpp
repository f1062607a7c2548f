#include "core/diff/terms/seeding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <atomic>
#include <stdexcept>

namespace limn {

SeedSegments parse_seed_segments(const std::string& name, const std::string& source) {
  if (name == "bsdf") return SeedSegments::Bsdf;
  if (name == "emitter") return SeedSegments::Emitter;
  if (name == "both") return SeedSegments::Both;
  throw std::invalid_argument(source + ": project_seed must be 'bsdf', 'emitter' or 'both' (got '" + name + "')");
}

std::vector<Projection> projected_seeds(const Scene& scene, const Projector& projector, uint64_t paths, SeedSegments which,
                                        int max_depth, uint64_t seed, int threads, SeedStats* stats) {
  constexpr uint64_t kBlock = 256;
  constexpr int kMaxVertices = 3;  // seed vertices after the camera ray
  const uint64_t blocks = (paths + kBlock - 1) / kBlock;
  std::vector<std::vector<Projection>> per_block(blocks);
  std::atomic<uint64_t> segments{0}, projected{0}, found{0}, rays{0};
  const int vertices = max_depth < 0 ? kMaxVertices : std::min(kMaxVertices, max_depth - 1);
  const bool use_bsdf = which != SeedSegments::Emitter, use_emitter = which != SeedSegments::Bsdf;
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, blocks, 1), [&](const tbb::blocked_range<uint64_t>& r) {
      for (uint64_t blk = r.begin(); blk != r.end(); ++blk) {
        std::vector<Projection>& out = per_block[blk];
        uint64_t seg = 0, rr = 0;
        for (uint64_t j = blk * kBlock; j < std::min(paths, (blk + 1) * kBlock); ++j) {
          Pcg32 rng = pixel_rng(mix_bits(seed ^ 0x7365656473ULL), j);
          const Vec2 film(rng.next_float() * scene.camera.width, rng.next_float() * scene.camera.height);
          const Ray camera_ray = scene.camera.generate_ray(film);
          Vec3 wi = -camera_ray.d;  // towards the previous vertex
          SurfaceInteraction si;
          ++rr;
          if (!scene.intersect(camera_ray, si)) continue;
          auto add = [&](const Vec3& xa, const SurfaceInteraction& hit) {
            ++seg;
            if (auto p = projector.project(xa, hit, rng)) out.push_back(*p);
          };
          for (int v = 0; v < vertices; ++v) {
            const Shape& shape = scene.shapes[si.shape];
            const Bsdf& bsdf = scene.bsdfs[shape.bsdf];
            const bool front = glm::dot(wi, si.ng) > 0.0f;
            if (use_emitter && !scene.emitters.empty()) {
              // The blocker of a shadow ray towards an emitter sample.
              const size_t e = std::min(scene.emitters.size() - 1, size_t(rng.next_float() * scene.emitters.size()));
              const EmitterSample es = sample_emitter(scene.emitters[e], scene.shapes, si.p, rng.next_2d(), rng.next_float());
              if (es.pdf > 0.0f) {
                Ray shadow = es.to_infinity ? spawn_ray(si, es.wi) : spawn_ray_to(si, es.p);
                SurfaceInteraction blocker;
                ++rr;
                if (scene.intersect(shadow, blocker)) add(si.p, blocker);
              }
            }
            const auto bs = bsdf.sample(si.frame.to_local(wi), rng.next_float(), rng.next_2d(), si.uv, front);
            if (!bs) break;
            const Vec3 wo = si.frame.to_world(bs->wo);
            SurfaceInteraction next;
            ++rr;
            if (!scene.intersect(spawn_ray(si, wo), next)) break;
            if (use_bsdf) add(si.p, next);
            wi = -wo;
            si = next;
          }
        }
        segments += seg;
        rays += rr;
      }
    });
  });
  std::vector<Projection> all;
  for (auto& b : per_block) {
    for (const Projection& p : b) found += p.found;
    projected += b.size();
    all.insert(all.end(), b.begin(), b.end());
  }
  if (stats) *stats = SeedStats{paths, segments, projected, found, rays};
  return all;
}

}  // namespace limn
