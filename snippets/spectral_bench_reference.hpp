// spectral_bench reference code in C++17: include this one header for all of it (microfacets and
// visible-normal sampling, Fresnel and thin film, dispersion and fluorescence). Header-only, no
// dependencies; everything is in namespace sbref. See docs/scene-format.md for the scene format
// these models belong to and reference_code/appearance.py for the tested numpy original.
#pragma once

#include "sb_dispersion.hpp"
#include "sb_fresnel.hpp"
#include "sb_microfacet.hpp"
