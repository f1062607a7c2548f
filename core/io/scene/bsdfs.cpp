#include "core/io/scene/bsdfs.h"

#include <map>
#include "core/io/formats/files.h"

namespace limn::io_detail {

struct ConductorIor {
  Spectrum eta, k;
};
// RGB approximations of measured complex IORs (values at roughly 650, 550 and 450 nm).
const std::map<std::string, ConductorIor>& conductor_table() {
  static const std::map<std::string, ConductorIor> t = {
      {"none", {Spectrum(0.0f), Spectrum(1.0f)}},
      {"Au", {Spectrum(0.143f, 0.374f, 1.442f), Spectrum(3.983f, 2.385f, 1.603f)}},
      {"Ag", {Spectrum(0.155f, 0.117f, 0.138f), Spectrum(4.828f, 3.122f, 2.147f)}},
      {"Cu", {Spectrum(0.200f, 0.924f, 1.102f), Spectrum(3.912f, 2.452f, 2.142f)}},
      {"Al", {Spectrum(1.657f, 0.880f, 0.521f), Spectrum(9.224f, 6.270f, 4.837f)}}};
  return t;
}

float ior_value(const Props& p, const std::string& k, float def) {
  static const std::map<std::string, float> names = {
      {"vacuum", 1.0f},        {"helium", 1.00004f},      {"hydrogen", 1.00013f}, {"air", 1.00028f},
      {"water", 1.3330f},      {"ethanol", 1.361f},       {"fused quartz", 1.458f}, {"pyrex", 1.470f},
      {"acrylic glass", 1.49f}, {"polypropylene", 1.49f}, {"bk7", 1.5046f},       {"sodium chloride", 1.544f},
      {"amber", 1.55f},        {"pet", 1.5750f},          {"diamond", 2.419f}};
  if (!p.has(k)) return def;
  const json& v = p.raw(k);
  float ior;
  if (v.is_string()) {
    auto it = names.find(v.get<std::string>());
    if (it == names.end()) p.fail("unknown material name '" + printable(v.get<std::string>(), 60) + "' for '" + k + "'");
    ior = it->second;
  } else {
    ior = p.number(k);
  }
  if (!(ior > 0.0f)) p.fail("'" + k + "' must be > 0 (got " + std::to_string(ior) + ")");
  return ior;
}

Microfacet load_microfacet(const Props& p) {
  Microfacet m;
  const std::string dist = p.string("distribution", "beckmann");
  if (dist == "ggx") m.type = MicrofacetType::GGX;
  else if (dist == "beckmann") m.type = MicrofacetType::Beckmann;
  else p.fail("distribution must be 'ggx' or 'beckmann' (got '" + printable(dist, 60) + "')");
  m.alpha = p.number("alpha", 0.1f);
  if (p.has("alpha_u") || p.has("alpha_v")) {
    const float au = p.number("alpha_u", m.alpha), av = p.number("alpha_v", m.alpha);
    if (au != av) p.fail("anisotropic roughness is not supported (alpha_u " + std::to_string(au) + " != alpha_v " + std::to_string(av) + ")");
    m.alpha = au;
  }
  if (!(m.alpha > 0.0f)) p.fail("alpha must be > 0 (got " + std::to_string(m.alpha) + "); use 'conductor' or 'dielectric' for smooth surfaces");
  m.sample_visible = p.boolean("sample_visible", true);
  return m;
}

void load_conductor_ior(const Props& p, Spectrum& eta, Spectrum& k) {
  if (p.has("eta") || p.has("k")) {
    if (p.has("material")) p.fail("give either 'material' or 'eta' and 'k', not both");
    eta = p.spectrum("eta", Spectrum(0.0f));
    k = p.spectrum("k", Spectrum(1.0f));
    return;
  }
  const std::string name = p.string("material", "none");
  auto it = conductor_table().find(name);
  if (it == conductor_table().end()) p.fail("unknown conductor material '" + printable(name, 60) + "' (known: none, Au, Ag, Cu, Al)");
  eta = it->second.eta;
  k = it->second.k;
}

BsdfModel load_bsdf_model(Context& ctx, const Props& p, const std::string& type, const std::string& id, bool& twosided) {
  if (type == "diffuse") return Diffuse{p.texture("reflectance", Spectrum(0.5f))};
  if (type == "conductor") {
    Conductor c;
    load_conductor_ior(p, c.eta, c.k);
    c.specular_reflectance = p.spectrum("specular_reflectance", Spectrum(1.0f));
    return c;
  }
  if (type == "roughconductor") {
    RoughConductor c;
    load_conductor_ior(p, c.eta, c.k);
    c.specular_reflectance = p.spectrum("specular_reflectance", Spectrum(1.0f));
    c.distribution = load_microfacet(p);
    return c;
  }
  if (type == "dielectric" || type == "roughdielectric") {
    const float eta = ior_value(p, "int_ior", 1.5046f) / ior_value(p, "ext_ior", 1.000277f);
    const Spectrum r = p.spectrum("specular_reflectance", Spectrum(1.0f)), t = p.spectrum("specular_transmittance", Spectrum(1.0f));
    if (std::abs(eta - 1.0f) < 1e-6f) p.fail("int_ior and ext_ior must differ (an index-matched interface is invisible)");
    if (type == "dielectric") return Dielectric{eta, r, t};
    return RoughDielectric{eta, r, t, load_microfacet(p)};
  }
  if (type == "twosided") {
    const auto kids = p.children();
    if (kids.size() != 1) p.fail("twosided needs exactly one nested bsdf (got " + std::to_string(kids.size()) + ")");
    p.mark_used(kids[0].first);
    if (kids[0].second->contains("id"))
      p.fail("the bsdf nested in twosided (under '" + printable(kids[0].first, 60) + "') takes the twosided's id '" + id + "'; remove its \"id\" " +
             brief(kids[0].second->at("id")));
    Bsdf inner = load_bsdf(ctx, *kids[0].second, id);
    if (inner.twosided) p.fail("twosided cannot wrap another twosided");
    if (inner.transmits()) p.fail("twosided cannot wrap a transmissive bsdf");
    twosided = true;
    return inner.model;
  }
  p.fail("unknown bsdf type '" + type + "' (known: " + known_of(Category::Bsdf) + ")");
}

Bsdf load_bsdf(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("bsdf", id, type));
  Bsdf b;
  b.id = id;
  b.model = load_bsdf_model(ctx, p, type, id, b.twosided);
  p.check_unused();
  return b;
}

int add_bsdf(Context& ctx, Bsdf b) {
  ctx.scene->bsdfs.push_back(std::move(b));
  return int(ctx.scene->bsdfs.size() - 1);
}

}  // namespace limn::io_detail
