// The sensor (perspective, with its nested film and sampler) and the integrator.
#pragma once
#include <cstdint>
#include <string>
#include "core/io/scene/props.h"

namespace limn::io_detail {

// Films have at most this many pixels (the image is held as float RGB).
inline constexpr uint64_t kMaxFilmPixels = uint64_t(1) << 26;  // e.g. 8192 x 8192

void load_sensor(Context& ctx, const json& j, const std::string& id);
void load_integrator(Context& ctx, const json& j, const std::string& id);

}  // namespace limn::io_detail
