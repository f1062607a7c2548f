// A loaded scene: shapes, materials, emitters, camera, integrator settings, the Embree
// acceleration structure, and the table of parameters users may edit between renders.
#pragma once
#include <memory>
#include <shared_mutex>
#include <string>
#include <vector>
#include "core/render/accel.h"
#include "core/render/bsdfs/bsdf.h"
#include "core/render/camera.h"
#include "core/render/emitters/emitter.h"

namespace limn {

// RenderOptions / DiffOptions max_depth meaning "the scene's integrator setting".
inline constexpr int kSceneMaxDepth = -2;

struct IntegratorSettings {
  std::string type = "path";  // "path" or "direct"
  int max_depth = -1;         // longest path in segments (Mitsuba: 1 = emitters seen directly); -1 = unbounded
  int rr_depth = 5;           // Russian roulette from this depth on
  bool hide_emitters = false; // directly visible emitters render black
  // Strategies combined by MIS ("direct" lets either be switched off, as Mitsuba's emitter_samples
  // / bsdf_samples; only 0 or 1 sample per strategy is supported).
  bool emitter_sampling = true;
  bool bsdf_sampling = true;
};

class Scene {
 public:
  std::string source = "<dict>";   // file the scene came from, for messages
  Camera camera;
  IntegratorSettings integrator;
  int spp = 16;
  std::vector<Shape> shapes;
  std::vector<Bsdf> bsdfs;
  std::vector<Emitter> emitters;
  std::vector<int> infinite_emitters;  // constant and envmap emitters, hit by escaping rays
  std::vector<std::string> warnings;   // unused parameters and other notes from loading

  // Validates, computes derived state and builds the acceleration structure (once, after loading).
  void build();
  bool intersect(const Ray& ray, SurfaceInteraction& si) const { return m_accel->intersect(ray, si); }
  bool occluded(const Ray& ray) const { return m_accel->occluded(ray); }
  // Rays so far that could not be traced (non-finite, or beyond Embree's range) and missed.
  uint64_t invalid_rays() const { return m_accel->invalid_rays(); }

  // Editable parameters, their values as of the last update().
  std::vector<Parameter>& parameters() { return m_params; }
  const Parameter* find_parameter(const std::string& name) const;
  // Applies edits made through parameter views since the last update(): validates them (throws
  // std::invalid_argument naming the parameter, index and value; the previous value is restored),
  // refits geometry that moved and recomputes derived state. Returns the names that changed.
  std::vector<std::string> update();

  // Held (shared) by every render for its whole duration; update() needs it exclusively and throws
  // std::runtime_error instead of waiting when a render runs in another thread.
  std::shared_lock<std::shared_mutex> render_lock() const { return std::shared_lock<std::shared_mutex>(m_mutex); }

  // Probability of choosing emitter i for next-event estimation (uniform selection).
  float emitter_selection_pdf() const { return emitters.empty() ? 0.0f : 1.0f / float(emitters.size()); }

 private:
  void collect_parameters();
  void validate_parameter(const Parameter& p) const;
  void validate_translation(size_t i) const;  // of m_params[i], a shape's translation
  void apply_parameter(const Parameter& p);
  std::unique_ptr<Accel> m_accel;
  mutable std::shared_mutex m_mutex;
  std::vector<Parameter> m_params;
  std::vector<std::vector<float>> m_snapshots;  // value of each parameter at the last update()
};

// The path length a render or derivative call uses: the scene's, or `requested` (>= -1) for the
// path integrator. Throws std::invalid_argument naming the scene for anything else.
inline int effective_max_depth(const Scene& scene, int requested) {
  if (requested == kSceneMaxDepth) return scene.integrator.max_depth;
  if (requested < -1)
    throw std::invalid_argument(scene.source + ": max_depth must be >= -1 (-1: unbounded), got " + std::to_string(requested));
  if (scene.integrator.type != "path")
    throw std::invalid_argument(scene.source + ": max_depth applies to the path integrator; this scene uses '" +
                                scene.integrator.type + "'");
  return requested;
}

}  // namespace limn
