// invsss reference shader: the 7-tap directional pass of the `sog` and `thesis`
// models (docs/model.md, section 3). Included by invsss_sog.hlsl and
// invsss_thesis.hlsl after the exported constants.
//
// Constants used (from `invsss export --format hlsl`):
//   sssLevel, correction, maxdd   the stretch factors (section 2)
//   passWidths[numPasses]         width of pass `passIndex` in scene units; the
//                                 footprint in pixels is stretch * passWidths[i]
//   tapOffsets[7], tapWeights[7]  tap positions in footprints (-1 .. 1) and weights

#ifndef INVSSS_SEVEN_TAP_HLSL
#define INVSSS_SEVEN_TAP_HLSL

#include "invsss_common.hlsl"

// One directional pass: Destination = Source blurred along passAxis with the
// width of pass passIndex, blended by the mask.
//   P(I; f)[p] = sum_k tapWeights[k] * I(p + tapOffsets[k] * f[p] along the axis)
// Dispatch ceil(width / 8) x ceil(height / 8) groups.
[numthreads(8, 8, 1)]
void BlurPassCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    // Footprint in pixels: the stretch along this pass's axis times the pass width.
    float footprint = InvsssStretch(p, passAxis) * passWidths[passIndex];
    float coordinate = passAxis == 0 ? float(p.x) : float(p.y);
    float4 centre = Source.Load(int3(p, 0));
    // The centre tap (offset 0) reads the pixel itself; the others are summed in
    // tap order, as invsss.passes.directional_pass does.
    float4 blurred = tapWeights[3] * centre;
    [unroll]
    for (int k = 0; k < 7; ++k)
    {
        if (k == 3)
            continue;
        blurred += tapWeights[k] * InvsssSampleAlong(p, passAxis, coordinate + tapOffsets[k] * footprint);
    }
    Destination[p] = InvsssMaskBlend(p, centre, blurred);
}

#endif // INVSSS_SEVEN_TAP_HLSL
