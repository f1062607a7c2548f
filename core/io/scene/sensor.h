// The sensor (perspective, with its nested film and sampler) and the integrator.
#pragma once
#include <string>
#include "core/io/scene/props.h"

namespace limn::io_detail {

void load_sensor(Context& ctx, const json& j, const std::string& id);
void load_integrator(Context& ctx, const json& j, const std::string& id);

}  // namespace limn::io_detail
