// invsss reference shader, model `thesis` (docs/model.md, section 5): the chain
// the 2020 thesis shipped (its Listing 4.1 and Figure 4.10).
//
// Build BlurPassCS (glslangValidator -D -V -S comp -e BlurPassCS) with the
// exported constants file `invsss_constants.hlsl` next to this file, and run,
// each pass on the output of the one before:
//
//   for i in 0 .. numPasses - 1: BlurPassCS(passIndex = i, passAxis = 0)   // all horizontal first
//   for i in 0 .. numPasses - 1: BlurPassCS(passIndex = i, passAxis = 1)   // then all vertical
//
// The last pass is the output; the profile's weights are not used (the chain
// is one Gaussian of variance v_1 + ... + v_K). passWidths[i] = sqrt(v_i) /
// tapSpread in the order of the params file; with one Gaussian of variance
// (7 tapSpread)^2 the footprint is 7 s pixels, Listing 4.1's kernel.
//
// Cost per pixel: 2 numPasses passes of 7 taps (13 texture reads each, plus 3
// depth reads for the stretch).

#include "invsss_constants.hlsl"
#include "invsss_seven_tap.hlsl"
