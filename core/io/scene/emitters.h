// Emitters at the top level of a scene: point, spot, directional, constant, envmap. (Area emitters are
// nested in shapes and loaded with them, shapes.cpp.)
#pragma once
#include <string>
#include "core/io/scene/props.h"

namespace limn::io_detail {

void load_emitter(Context& ctx, const json& j, const std::string& id);

}  // namespace limn::io_detail
