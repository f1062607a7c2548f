// pybind11 module limn._core: converts between numpy/Python and the C++ core, nothing more.
// The Python package (bindings/limn) builds the user-facing API on top of it.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <exception>
#include <functional>
#include "core/diff/render_diff.h"
#include "core/io/sdf_from_mesh.h"
#include "core/render/accel.h"
#include "core/io/formats/image_io.h"
#include "core/io/formats/mesh_io.h"
#include "core/io/scene_loader.h"
#include "core/optim/large_steps.h"
#include "core/render/integrators/render.h"

namespace py = pybind11;
using namespace limn;

namespace {

using SceneHandle = std::shared_ptr<Scene>;

ArrayData to_array_data(const py::array& a) {
  ArrayData out;
  for (py::ssize_t i = 0; i < a.ndim(); ++i) out.shape.push_back(size_t(a.shape(i)));
  out.integer = py::dtype::of<int64_t>().kind() == a.dtype().kind() || a.dtype().kind() == 'u';
  auto as_double = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  if (!as_double) throw std::invalid_argument("cannot convert an array of dtype " + std::string(py::str(a.dtype())) + " to numbers");
  out.values.assign(as_double.data(), as_double.data() + as_double.size());
  return out;
}

py::array_t<float> image_to_numpy(Image img) {
  auto* owned = new std::vector<float>(std::move(img.rgb));
  py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<float>*>(p); });
  return py::array_t<float>({py::ssize_t(img.height), py::ssize_t(img.width), py::ssize_t(3)}, owned->data(), free_when_done);
}

Image numpy_to_image(const py::array& a0) {
  auto a = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a0);
  if (!a || !(a.ndim() == 3 && a.shape(2) == 3) && a.ndim() != 2)
    throw std::invalid_argument("image must be an array of shape (H, W, 3) or (H, W)");
  Image img{int(a.shape(1)), int(a.shape(0)), {}};
  img.rgb.resize(size_t(img.width) * img.height * 3);
  const float* src = a.data();
  if (a.ndim() == 3) std::copy(src, src + img.rgb.size(), img.rgb.begin());
  else
    for (size_t i = 0; i < size_t(img.width) * img.height; ++i) img.rgb[3 * i] = img.rgb[3 * i + 1] = img.rgb[3 * i + 2] = src[i];
  return img;
}

// Progress callback run with the GIL; a pending signal (Ctrl-C) or an exception from the callback
// cancels the computation and is kept in `error` to be re-raised afterwards.
std::function<bool(float)> progress_adapter(py::object progress, std::exception_ptr& error) {
  return [progress, &error](float fraction) -> bool {
    py::gil_scoped_acquire gil;
    try {
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      if (progress.is_none()) return true;
      py::object r = progress(fraction);
      return r.is_none() || r.cast<bool>();
    } catch (...) {
      if (!error) error = std::current_exception();
      return false;
    }
  };
}

py::dict diff_stats_dict(const DiffStats& st) {
  py::dict d;
  d["seconds"] = st.seconds;
  d["paths"] = st.paths;
  d["rays"] = st.rays;
  d["invalid_paths"] = st.invalid_paths;
  d["summary"] = st.summary;
  return d;
}

// The derivative options Python sees (Scene.render_forward / render_backward keywords), each with
// how it is read into DiffOptions and how its default is reported: bindings/limn/scene.py takes
// its defaults from here (diff_option_defaults), so they live in the C++ structs only, and the
// core validates them (validate_diff_options). Python's None is converted where C++ has a sentinel.
struct DiffOptionField {
  const char* name;
  std::function<void(DiffOptions&, const py::handle&)> set;
  std::function<py::object(const DiffOptions&)> get;
};

// A field read and reported as its own type; `member` returns a reference into DiffOptions.
template <typename T, typename Member>
DiffOptionField field(const char* name, Member member) {
  return {name, [member](DiffOptions& o, const py::handle& v) { member(o) = v.cast<T>(); },
          [member](const DiffOptions& o) { return py::cast(T(member(const_cast<DiffOptions&>(o)))); }};
}

// A term's sample count: Python's None is C++'s -1 (the call's spp); Python gives no negative counts.
template <typename Member>
DiffOptionField term_count(const char* name, Member member) {
  return {name,
          [name, member](DiffOptions& o, const py::handle& v) {
            if (v.is_none()) {
              member(o) = -1;
              return;
            }
            const int n = v.cast<int>();
            if (n < 0) throw std::invalid_argument(std::string(name) + " must be >= 0 (None: spp; got " + std::to_string(n) + ")");
            member(o) = n;
          },
          [member](const DiffOptions& o) {
            const int n = member(const_cast<DiffOptions&>(o));
            return n == -1 ? py::object(py::none()) : py::object(py::cast(n));
          }};
}

const std::vector<DiffOptionField>& diff_option_fields() {
  static const std::vector<DiffOptionField> fields = {
      // None: the scene's sample count (C++ 0).
      {"spp", [](DiffOptions& o, const py::handle& v) { o.spp = v.is_none() ? 0 : v.cast<int>(); },
       [](const DiffOptions& o) { return o.spp == 0 ? py::object(py::none()) : py::object(py::cast(o.spp)); }},
      // None: spp (C++ -1); 0 switches the term off.
      term_count("spp_interior", [](DiffOptions& o) -> int& { return o.spp_interior; }),
      term_count("spp_primary", [](DiffOptions& o) -> int& { return o.spp_primary; }),
      term_count("spp_boundary", [](DiffOptions& o) -> int& { return o.spp_boundary; }),
      field<std::string>("boundary_sampler", [](DiffOptions& o) -> std::string& { return o.boundary_sampler; }),
      field<std::string>("boundary_parts", [](DiffOptions& o) -> std::string& { return o.boundary_parts; }),
      {"seed", [](DiffOptions& o, const py::handle& v) {
         const long long seed = v.cast<long long>();
         if (seed < 0) throw std::invalid_argument("seed must be >= 0 (got " + std::to_string(seed) + ")");
         o.seed = uint64_t(seed);
       },
       [](const DiffOptions& o) { return py::cast(o.seed); }},
      field<int>("threads", [](DiffOptions& o) -> int& { return o.threads; }),
      field<std::string>("guiding", [](DiffOptions& o) -> std::string& { return o.guiding; }),
      field<bool>("projective", [](DiffOptions& o) -> bool& { return o.projective; }),
      field<std::string>("project_seed", [](DiffOptions& o) -> std::string& { return o.project_seed; }),
      field<int>("grid_resolution", [](DiffOptions& o) -> int& { return o.grid_resolution; }),
      field<int>("grid_octaves", [](DiffOptions& o) -> int& { return o.grid_octaves; }),
      field<int>("guiding_spp", [](DiffOptions& o) -> int& { return o.guiding_spp; }),
      // 0: the guide's default (seeds_per_pixel); Python says None.
      {"guiding_seeds", [](DiffOptions& o, const py::handle& v) {
         if (!v.is_none() && v.cast<int>() < 1)
           throw std::invalid_argument("guiding_seeds must be >= 1 or None (got " + std::to_string(v.cast<int>()) + ")");
         o.guiding_seeds = v.is_none() ? 0 : v.cast<int>();
       },
       [](const DiffOptions& o) { return o.guiding_seeds == 0 ? py::object(py::none()) : py::object(py::cast(o.guiding_seeds)); }},
      field<int>("octree_slices", [](DiffOptions& o) -> int& { return o.octree.slices; }),
      field<int>("octree_max_depth", [](DiffOptions& o) -> int& { return o.octree.max_depth; }),
      field<int>("octree_leaf_samples", [](DiffOptions& o) -> int& { return o.octree.leaf_samples; }),
      field<size_t>("octree_max_leaves", [](DiffOptions& o) -> size_t& { return o.octree.max_leaves; }),
      field<int>("octree_refine_rounds", [](DiffOptions& o) -> int& { return o.octree.refine_rounds; }),
      field<float>("octree_refine_factor", [](DiffOptions& o) -> float& { return o.octree.refine_factor; }),
      field<float>("octree_grid_mix", [](DiffOptions& o) -> float& { return o.octree_grid_mix; }),
      field<int>("octree_training", [](DiffOptions& o) -> int& { return o.octree_training; }),
      field<float>("direction_mix", [](DiffOptions& o) -> float& { return o.direction_mix; }),
      field<int>("direction_resolution", [](DiffOptions& o) -> int& { return o.direction_resolution; }),
      field<int>("direction_octaves", [](DiffOptions& o) -> int& { return o.direction_octaves; }),
      field<int>("guide_refresh", [](DiffOptions& o) -> int& { return o.guide_refresh; }),
      field<float>("guide_refresh_threshold", [](DiffOptions& o) -> float& { return o.guide_refresh_threshold; }),
      field<bool>("heightfield_mipmap", [](DiffOptions& o) -> bool& { return o.heightfield.search.use_mipmap; }),
      field<bool>("heightfield_curvature_test", [](DiffOptions& o) -> bool& { return o.heightfield.search.curvature_test; }),
      field<bool>("heightfield_reparam", [](DiffOptions& o) -> bool& { return o.heightfield.reparameterize; }),
      field<bool>("heightfield_delta_edges", [](DiffOptions& o) -> bool& { return o.heightfield.delta_edges; }),
      field<float>("heightfield_interval_mix", [](DiffOptions& o) -> float& { return o.heightfield.interval_uniform_share; }),
      field<bool>("heightfield_camera_every_interval", [](DiffOptions& o) -> bool& { return o.heightfield.camera_every_interval; }),
      field<float>("theta_subrange", [](DiffOptions& o) -> float& { return o.heightfield.theta_subrange_degrees; }),
      field<bool>("shading_horizon", [](DiffOptions& o) -> bool& { return o.shading_horizon; }),
      // The scene's own max_depth unless set; Python says None.
      {"max_depth", [](DiffOptions& o, const py::handle& v) { o.max_depth = v.is_none() ? kSceneMaxDepth : v.cast<int>(); },
       [](const DiffOptions& o) { return o.max_depth == kSceneMaxDepth ? py::object(py::none()) : py::object(py::cast(o.max_depth)); }},
  };
  return fields;
}

// DiffOptions from the keyword options (an unknown key is refused; the core validates the values).
DiffOptions diff_options(const py::dict& options) {
  DiffOptions o;
  const auto& fields = diff_option_fields();
  for (const auto& [key, value] : options) {
    const std::string k = py::str(key);
    const auto f = std::find_if(fields.begin(), fields.end(), [&](const DiffOptionField& d) { return k == d.name; });
    if (f == fields.end()) throw std::invalid_argument("unknown derivative option '" + k + "'");
    try {
      f->set(o, value);
    } catch (const py::cast_error&) {  // e.g. an int beyond C++'s int: pybind11's message names neither the option nor the value
      std::string got = py::repr(value);
      if (got.size() > 80) got = got.substr(0, 80) + "...";
      throw std::invalid_argument("derivative option '" + k + "' has the wrong type or is out of range (got " + got + ")");
    }
  }
  return o;
}

// Every option's default, from a default-constructed DiffOptions.
py::dict diff_option_defaults() {
  const DiffOptions o;
  py::dict d;
  for (const auto& f : diff_option_fields()) d[f.name] = f.get(o);
  return d;
}

// Runs f with the GIL released; a cancellation caused by the callback re-raises its error.
template <typename F>
auto run_released(std::exception_ptr& error, F&& f) {
  try {
    py::gil_scoped_release release;
    auto r = f();
    return r;
  } catch (const RenderCancelled&) {
    if (error) std::rethrow_exception(error);
    throw;
  }
}

// Render with the GIL released. The progress callback (if any) runs with the GIL re-acquired;
// it also gives Ctrl-C a chance: a pending signal cancels the render and is re-raised here.
py::tuple render_scene(const SceneHandle& scene, int spp, uint64_t seed, int threads, py::object progress, py::object max_depth) {
  RenderOptions opt;
  if (!max_depth.is_none()) opt.max_depth = max_depth.cast<int>();
  opt.spp = spp;
  opt.seed = seed;
  opt.threads = threads;
  std::exception_ptr error;
  opt.progress = progress_adapter(progress, error);
  RenderStats stats;
  Image img = run_released(error, [&] { return render(*scene, opt, &stats); });
  if (error) std::rethrow_exception(error);  // e.g. Ctrl-C seen at the final call
  py::dict s;
  s["seconds"] = stats.seconds;
  s["samples"] = stats.samples;
  s["rays"] = stats.rays;
  s["invalid_samples"] = stats.invalid_samples;
  s["invalid_rays"] = stats.invalid_rays;
  s["spp"] = spp > 0 ? spp : scene->spp;
  return py::make_tuple(image_to_numpy(std::move(img)), s);
}

py::tuple render_forward_py(const SceneHandle& scene, const std::vector<std::string>& names, const std::vector<py::array>& tangents,
                            const py::dict& options, py::object progress, GuideCache* cache) {
  const DiffParams params(*scene, names);
  if (tangents.size() != params.params().size()) throw std::invalid_argument("one tangent per differentiable parameter expected");
  std::vector<double> t(params.slot_count(), 0.0);
  for (size_t i = 0; i < tangents.size(); ++i) {
    auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(tangents[i]);
    const DiffParam& p = params.params()[i];
    if (!a || size_t(a.size()) != p.size) throw std::invalid_argument("tangent of '" + p.name + "' has the wrong size");
    std::copy(a.data(), a.data() + a.size(), t.begin() + long(p.offset));
  }
  DiffOptions opt = diff_options(options);
  opt.guide_cache = cache;
  std::exception_ptr error;
  opt.progress = progress_adapter(progress, error);
  DiffStats st;
  Image img = run_released(error, [&] { return render_forward(*scene, params, t, opt, &st); });
  if (error) std::rethrow_exception(error);
  return py::make_tuple(image_to_numpy(std::move(img)), diff_stats_dict(st));
}

py::tuple render_backward_py(const SceneHandle& scene, const std::vector<std::string>& names, const py::array& adjoint,
                             const py::dict& options, py::object progress, GuideCache* cache) {
  const DiffParams params(*scene, names);
  Image adj = numpy_to_image(adjoint);
  DiffOptions opt = diff_options(options);
  opt.guide_cache = cache;
  std::exception_ptr error;
  opt.progress = progress_adapter(progress, error);
  DiffStats st;
  std::vector<double> g = run_released(error, [&] { return render_backward(*scene, params, adj, opt, &st); });
  if (error) std::rethrow_exception(error);
  py::list grads;
  for (const DiffParam& p : params.params()) {
    std::vector<py::ssize_t> shape(p.shape.begin(), p.shape.end());
    py::array_t<float> a(shape);
    float* dst = a.mutable_data();
    for (size_t i = 0; i < p.size; ++i) dst[i] = float(g[p.offset + i]);
    grads.append(a);
  }
  return py::make_tuple(grads, diff_stats_dict(st));
}

py::array parameter_view(const SceneHandle& scene, const std::string& name) {
  const Parameter* p = scene->find_parameter(name);
  if (!p) throw py::key_error("unknown parameter '" + name + "'");
  std::vector<py::ssize_t> shape(p->shape.begin(), p->shape.end());
  // The view keeps the scene alive through its base object.
  return py::array_t<float>(shape, p->data, py::cast(scene));
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "limn core (C++): scene loading, rendering, image and mesh I/O";
  py::register_exception<RenderCancelled>(m, "RenderCancelled");

  py::class_<GuideCache>(m, "GuideCache", "Guides kept between derivative calls (Scene.render_forward/backward)")
      .def(py::init<>())
      .def_readonly("builds", &GuideCache::builds)
      .def_readonly("reuses", &GuideCache::reuses)
      .def_readonly("build_seconds", &GuideCache::build_seconds)
      .def("clear", [](GuideCache& c) { c = GuideCache{}; });

  py::class_<Scene, SceneHandle>(m, "Scene")
      .def("render", &render_scene, py::arg("spp") = 0, py::arg("seed") = 0, py::arg("threads") = 0, py::arg("progress") = py::none(),
           py::arg("max_depth") = py::none(),
           "Render; returns (image (H, W, 3) float32, stats dict). Releases the GIL.")
      .def("parameter_names", [](const SceneHandle& s) {
        std::vector<std::string> names;
        for (const Parameter& p : s->parameters()) names.push_back(p.name);
        return names;
      })
      .def("parameter", &parameter_view, "Writable float32 view of a parameter")
      .def("faces", [](const SceneHandle& s, const std::string& id) {
        for (const Shape& sh : s->shapes) {
          if (sh.id != id) continue;
          const Mesh* mesh = std::get_if<Mesh>(&sh.geometry);  // faces are a mesh's own parameter layout
          if (!mesh) throw std::invalid_argument(s->source + ": shape '" + id + "' is a " + sh.type + ", not a mesh");
          const Mesh& m = *mesh;
          py::array_t<int32_t> f({py::ssize_t(m.indices.size() / 3), py::ssize_t(3)});
          std::copy(m.indices.begin(), m.indices.end(), f.mutable_data());
          return f;
        }
        throw std::invalid_argument(s->source + ": no shape '" + id + "'");
      }, py::arg("id"), "Triangle indices (F, 3) of mesh shape `id`, into its welded vertex_positions")
      .def("update", &Scene::update, "Apply parameter edits; returns the names that changed")
      .def("render_forward", &render_forward_py, py::arg("names"), py::arg("tangents"), py::arg("options"),
           py::arg("progress") = py::none(), py::arg("guide_cache") = nullptr)
      .def("render_backward", &render_backward_py, py::arg("names"), py::arg("adjoint"), py::arg("options"),
           py::arg("progress") = py::none(), py::arg("guide_cache") = nullptr)
      .def_property_readonly("width", [](const Scene& s) { return s.camera.width; })
      .def_property_readonly("height", [](const Scene& s) { return s.camera.height; })
      .def_property_readonly("spp", [](const Scene& s) { return s.spp; })
      .def_property_readonly("source", [](const Scene& s) { return s.source; })
      .def_property_readonly("warnings", [](const Scene& s) { return s.warnings; })
      .def_property_readonly("shape_ids", [](const Scene& s) {
        std::vector<std::string> ids;
        for (const Shape& sh : s.shapes) ids.push_back(sh.id);
        return ids;
      })
      .def_property_readonly("integrator", [](const Scene& s) {
        py::dict d;
        d["type"] = s.integrator.type;
        d["max_depth"] = s.integrator.max_depth;
        d["rr_depth"] = s.integrator.rr_depth;
        return d;
      });

  m.def("load_file", [](const std::string& path) { return SceneHandle(load_scene_file(path)); }, py::arg("path"),
        py::call_guard<py::gil_scoped_release>());
  m.def("load_json", [](const std::string& text, const std::string& source, const std::string& base_dir, const std::vector<py::array>& arrays) {
        std::vector<ArrayData> data;
        for (const py::array& a : arrays) data.push_back(to_array_data(a));
        nlohmann::json j;
        try {
          j = nlohmann::json::parse(text);
        } catch (const nlohmann::json::parse_error& e) {
          throw std::invalid_argument(source + ": malformed description: " + e.what());
        }
        py::gil_scoped_release release;
        return SceneHandle(load_scene_dict(j, source, base_dir, data));
      }, py::arg("text"), py::arg("source"), py::arg("base_dir"), py::arg("arrays"));

  m.def("read_image", [](const std::string& path, bool raw) {
        Bitmap b = read_image(path, raw);
        return image_to_numpy(Image{b.width, b.height, std::move(b.rgb)});
      }, py::arg("path"), py::arg("raw") = false);
  m.def("write_image", [](const std::string& path, const py::array& img) { write_image(path, numpy_to_image(img)); },
        py::arg("path"), py::arg("image"));
  m.def("write_ply", [](const std::string& path, py::array_t<float, py::array::c_style | py::array::forcecast> v,
                        py::array_t<uint32_t, py::array::c_style | py::array::forcecast> f) {
        if (v.ndim() != 2 || v.shape(1) != 3) throw std::invalid_argument("write_ply: positions must have shape (N, 3)");
        if (f.ndim() != 2 || f.shape(1) != 3) throw std::invalid_argument("write_ply: faces must have shape (F, 3)");
        write_ply(path, std::vector<float>(v.data(), v.data() + v.size()), std::vector<uint32_t>(f.data(), f.data() + f.size()));
      }, py::arg("path"), py::arg("positions"), py::arg("faces"));
  m.def("sdf_from_mesh", [](py::array_t<double, py::array::c_style | py::array::forcecast> v,
                            py::array_t<int64_t, py::array::c_style | py::array::forcecast> f, int resolution, double padding,
                            const std::string& what, py::object progress) {
        if (v.ndim() != 2 || v.shape(1) != 3)
          throw std::invalid_argument("sdf_from_mesh: " + what + ": vertices must have shape (N, 3)");
        if (f.ndim() != 2 || f.shape(1) != 3) throw std::invalid_argument("sdf_from_mesh: " + what + ": faces must have shape (F, 3)");
        std::vector<double> vertices(v.data(), v.data() + v.size());
        std::vector<int64_t> faces(f.data(), f.data() + f.size());
        std::exception_ptr error;
        auto callback = progress_adapter(progress, error);
        SdfFromMesh g = run_released(error, [&] { return sdf_from_mesh(vertices, faces, resolution, padding, what, callback); });
        auto* owned = new std::vector<float>(std::move(g.values));
        py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<float>*>(p); });
        py::array_t<float> data({py::ssize_t(g.nz), py::ssize_t(g.ny), py::ssize_t(g.nx)}, owned->data(), free_when_done);
        return py::make_tuple(data, py::make_tuple(g.origin[0], g.origin[1], g.origin[2]),
                              py::make_tuple(g.extent[0], g.extent[1], g.extent[2]), g.voxel, g.sign_disagreements);
      }, py::arg("vertices"), py::arg("faces"), py::arg("resolution"), py::arg("padding"), py::arg("what"),
      py::arg("progress") = py::none());
  m.def("embree_error_count", &EmbreeDevice::error_count);
  m.def("diff_option_defaults", &diff_option_defaults, "Derivative options and their defaults (DiffOptions)");

  using Rows = py::array_t<double, py::array::c_style | py::array::forcecast>;
  auto check_rows = [](const LargeSteps& ls, const Rows& a, const char* what) {
    if (a.ndim() != 2 || a.shape(1) < 1 || size_t(a.shape(0)) != ls.vertex_count())
      throw std::invalid_argument(std::string("LargeSteps: ") + what + " must have shape (" + std::to_string(ls.vertex_count()) + ", k)");
  };
  py::class_<LargeSteps>(m, "LargeSteps")
      .def(py::init([](py::array_t<int64_t, py::array::c_style | py::array::forcecast> faces, size_t n, double lambda) {
             if (faces.ndim() != 2 || faces.shape(1) != 3) throw std::invalid_argument("LargeSteps: faces must have shape (F, 3)");
             std::vector<uint32_t> f(size_t(faces.size()));
             for (py::ssize_t i = 0; i < faces.size(); ++i) {
               if (faces.data()[i] < 0) throw std::invalid_argument("LargeSteps: negative face index");
               f[size_t(i)] = uint32_t(faces.data()[i]);
             }
             return LargeSteps(f, n, lambda);
           }), py::arg("faces"), py::arg("vertex_count"), py::arg("lambda_"))
      .def("to_u", [check_rows](const LargeSteps& ls, const Rows& x) {
        check_rows(ls, x, "x");
        Rows u({py::ssize_t(ls.vertex_count()), x.shape(1)});
        ls.to_u(x.data(), u.mutable_data(), int(x.shape(1)));
        return u;
      })
      .def("from_u", [check_rows](const LargeSteps& ls, const Rows& u) {
        check_rows(ls, u, "u");
        Rows x({py::ssize_t(ls.vertex_count()), u.shape(1)});
        {
          py::gil_scoped_release release;
          ls.from_u(u.data(), x.mutable_data(), int(u.shape(1)));
        }
        return x;
      });
}
