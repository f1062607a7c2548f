// BSDF loaders: diffuse, conductor, roughconductor, dielectric, roughdielectric, twosided.
#pragma once
#include <string>
#include "core/io/scene/props.h"

namespace limn::io_detail {

// Loads a bsdf object (top-level, nested in a shape, or wrapped by twosided); `id` names it.
Bsdf load_bsdf(Context& ctx, const json& j, const std::string& id);
// Appends to the scene's bsdfs; returns the index.
int add_bsdf(Context& ctx, Bsdf b);

}  // namespace limn::io_detail
