// invsss reference shader, model `sog` (docs/model.md, section 5): the
// sum-of-Gaussians profile applied one Gaussian at a time (d'Eon & Luebke 2007,
// accumulated as in Jimenez et al. 2009).
//
// Build each entry point separately (glslangValidator -D -V -S comp -e NAME, or
// your engine's compute kernel pragma), with the exported constants file
// `invsss_constants.hlsl` (`invsss export params.json --format hlsl`) next to
// this file. Run, with the mask and the depth bound throughout:
//
//   accum = 0 (any finite value: blendFactors[0] is always 1)
//   layer = the lit image without scattering
//   for i in 0 .. numPasses - 1:          // the layers, by increasing variance
//       BlurPassCS(passIndex = i, passAxis = 0): layer -> tmp    (horizontal)
//       BlurPassCS(passIndex = i, passAxis = 1): tmp -> layer    (vertical)
//       AccumulateCS(passIndex = i): accum = lerp(accum, layer, blendFactors[i])
//   accum is the scattered image: sum_i layerWeights[i] * B_i.
//
// Layer i is layer i-1 blurred by the difference of the sorted variances
// (passWidths[i] = sqrt(v_i - v_(i-1)) / tapSpread): do not reorder the passes
// or the blend factors, and do not restart each layer from the source image.
// blendFactors and layerWeights are float3 per layer for an RGB profile and
// float for a grey one; both convert to float3 below.
//
// Cost per pixel: 2 numPasses passes of 7 taps (2 texture reads per tap off
// the centre, 13 per pass, plus 3 depth reads for the stretch), and numPasses
// accumulations; 10 passes for the default 5-Gaussian profile.

#include "invsss_constants.hlsl"
#include "invsss_seven_tap.hlsl"

// accum = lerp(accum, layer, blendFactors[passIndex]), with the layer in Source
// and accum in Destination (read and written in place).
[numthreads(8, 8, 1)]
void AccumulateCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float3 blend = blendFactors[passIndex];
    float4 layer = Source.Load(int3(p, 0));
    float4 accum = Destination[p];
    Destination[p] = float4(lerp(accum.rgb, layer.rgb, blend), layer.a);
}
