// render_forward / render_backward: derivative images and parameter gradients.
//
// Terms: the interior term (interior.h) for every parameter kind, the primary-visibility boundary
// term (primary.h) and the indirect boundary term (indirect.h: Eq. 4's perimeter and interior
// parts), both over the boundaries the shape kinds provide (core/diff/shapes/). A scene with a
// heightfield and differentiable geometry uses the heightfield estimator
// (core/diff/estimators/heightfield.h) instead of all three: its reparameterised sampling covers the
// visibility changes itself. Options: diff_options.h; guiding of the indirect term and the guide
// cache: guide_builder.h. The summary says what was computed and what was skipped.
#pragma once
#include <vector>
#include "core/diff/diff_options.h"
#include "core/diff/guide_builder.h"
#include "core/render/integrators/render.h"

namespace limn {

// Derivative image d(image)/d(theta) along `tangent` (one value per slot of `params`).
Image render_forward(const Scene& scene, const DiffParams& params, const std::vector<double>& tangent,
                     const DiffOptions& options, DiffStats* stats = nullptr);

// Gradient of sum(adjoint * image) with respect to every slot of `params`.
std::vector<double> render_backward(const Scene& scene, const DiffParams& params, const Image& adjoint,
                                    const DiffOptions& options, DiffStats* stats = nullptr);

}  // namespace limn
