// invsss reference shader: the light-aware terms applied after the blur
// (docs/model.md, section 8): shift, grazing and incidence.
//
// Build LightTermsCS (glslangValidator -D -V -S comp -e LightTermsCS) with the
// exported constants file `invsss_constants.hlsl` next to this file (it holds
// lightShift, grazingGain and incidenceGain when the fit used one of these
// terms), and run it once on the blurred image (the model's output) in Source:
//
//   LightTermsCS: blurred -> out
//
// Normal and ToLight are view-space unit vectors, x right, y up, z towards the
// camera (negate z for a +z-forward view space). A term whose constant is 0
// changes nothing. The shift uses the stretch factors of the blur
// (sssLevel, correction, maxdd and the depth slopes), whatever the model.
// This is the exact counterpart of the exported invsssLightTerms(), which
// reads the shifted image with a bilinear sampler instead (see
// invsss_common.hlsl on sampler precision).
//
// Cost per pixel: 4 texture reads for the shifted image, 2 for the buffers,
// 5 depth reads for the stretch factors.

#include "invsss_constants.hlsl"
#include "invsss_common.hlsl"

[numthreads(8, 8, 1)]
void LightTermsCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float3 toLight = ToLight.Load(int3(p, 0)).xyz;
    float3 normal = Normal.Load(int3(p, 0)).xyz;
    float2 stretch = float2(InvsssStretch(p, 0), InvsssStretch(p, 1));
    // The direction the light travels, in image axes (x right, rows down).
    float2 travel = float2(-toLight.x, toLight.y);
    float2 delta = lightShift * float2(stretch.x * travel.x, stretch.y * travel.y);   // pixels
    float4 shifted = InvsssSampleBilinear(float2(p) - delta);
    shifted *= 1.0 + grazingGain * (1.0 - saturate(normal.z));
    shifted *= 1.0 + incidenceGain * (1.0 - saturate(dot(normal, toLight)));
    float4 centre = Source.Load(int3(p, 0));
    Destination[p] = InvsssMaskBlend(p, centre, float4(shifted.rgb, centre.a));
}
