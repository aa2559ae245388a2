// The one header to include: simdvol's whole public API.
//
//   CPU (simdvol::core):   volumes, I/O, phantoms, views, the serial
//                          reference stages and renderer, the cost model of
//                          the thesis's machine (costmodel.hpp)
//   OpenCL (simdvol::simdvol): the device layer (device.hpp: a Device of its
//                          own or wrapping the caller's cl_context and
//                          cl_command_queue), the per-stage enqueue_*
//                          functions and the render engine
//
// The kernel ABI (arguments, buffer layouts, work sizes, stage order) is in
// docs/KERNELS.md of the source tree, installed as share/doc/simdvol/KERNELS.md
// (under the install prefix); the structs shared with the kernels in
// simdvol_shared.h.
#pragma once

// CPU library
#include "simdvol/classify.hpp"
#include "simdvol/composite.hpp"
#include "simdvol/costmodel.hpp"
#include "simdvol/error.hpp"
#include "simdvol/image.hpp"
#include "simdvol/io.hpp"
#include "simdvol/local.hpp"
#include "simdvol/match.hpp"
#include "simdvol/mc.hpp"
#include "simdvol/mismatch.hpp"
#include "simdvol/pe_array.hpp"
#include "simdvol/phantom.hpp"
#include "simdvol/render.hpp"
#include "simdvol/resample.hpp"
#include "simdvol/shade.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/view.hpp"
#include "simdvol/volume.hpp"

// OpenCL layer
#include "simdvol/device.hpp"
#include "simdvol/engine.hpp"
#include "simdvol/layout.hpp"
#include "simdvol/local_cl.hpp"
#include "simdvol/match_cl.hpp"
#include "simdvol/mc_cl.hpp"
#include "simdvol/stages.hpp"
#include "simdvol/swap_cl.hpp"
