// invsss reference shader, model `separable` (docs/model.md, section 5):
// Jimenez et al. 2015, one horizontal and one vertical pass of numTaps taps.
//
// Build SeparablePassCS (glslangValidator -D -V -S comp -e SeparablePassCS)
// with the exported constants file `invsss_constants.hlsl` next to this file,
// and run
//
//   SeparablePassCS(passAxis = 0): image -> tmp     (horizontal)
//   SeparablePassCS(passAxis = 1): tmp -> out       (vertical)
//
// Tap n of pixel p reads p + kernelOffsets[n] * sssLevel / depth along the axis
// (scene units to pixels; no correction term, so correction and maxdd are
// unused) and is weighted per channel by kernelWeights[n]. `kernel` holds the
// same numbers in iryoku/separable-sss's float4 layout (rgb weight, a offset,
// centre first); this shader sums the taps in offset order, as invsss does.
// The follow-surface option of Jimenez's shader (invsss render's
// follow_surface) is not exported and not implemented here: it must be 0.
//
// Cost per pixel: 2 passes of numTaps taps (2 texture reads per tap off the
// centre, plus 1 depth read).

#include "invsss_constants.hlsl"
#include "invsss_common.hlsl"

[numthreads(8, 8, 1)]
void SeparablePassCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float scale = sssLevel / InvsssDepthAt(p);   // pixels per scene unit
    float coordinate = passAxis == 0 ? float(p.x) : float(p.y);
    float4 centre = Source.Load(int3(p, 0));
    float3 blurred = float3(0.0, 0.0, 0.0);
    for (int n = 0; n < numTaps; ++n)
    {
        float4 tap = InvsssSampleAlong(p, passAxis, coordinate + kernelOffsets[n] * scale);
        blurred += kernelWeights[n] * tap.rgb;
    }
    Destination[p] = InvsssMaskBlend(p, centre, float4(blurred, centre.a));
}
