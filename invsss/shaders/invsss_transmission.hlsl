// invsss reference shader: the transmission term (docs/model.md, section 8), light
// from a key light behind a thin part, added to the source before the blur.
//
// A renderer adds invsssTransmittedLight(thickness, keyIrradiance, normal, toLight),
// the function the exported constants file holds when the fit used the term (with
// transmissionTint and thicknessScale), to the diffuse lighting its blur spreads. This
// compute version does the same to an image already lit:
//
//   TransmissionCS: source -> source + mask * invsssTransmittedLight(t, E, n, l)
//
// with t from Thickness (mm) and E from KeyIrradiance (the albedo times the key
// light's unshadowed irradiance). Run it after LawCS when the fit used the law too,
// then the model's passes. Build with glslangValidator -D -V -S comp -e TransmissionCS,
// the exported `invsss_constants.hlsl` next to this file.

#include "invsss_constants.hlsl"
#include "invsss_common.hlsl"

[numthreads(8, 8, 1)]
void TransmissionCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float3 normal = Normal.Load(int3(p, 0)).xyz;
    float3 toLight = ToLight.Load(int3(p, 0)).xyz;
    float4 source = Source.Load(int3(p, 0));
    float thickness = Thickness.Load(int3(p, 0));
    float3 keyIrradiance = KeyIrradiance.Load(int3(p, 0)).rgb;
    float mask = Mask.Load(int3(p, 0));
    float3 lit = source.rgb + mask * invsssTransmittedLight(thickness, keyIrradiance, normal, toLight);
    Destination[p] = float4(lit, source.a);
}
