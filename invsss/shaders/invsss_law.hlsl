// invsss reference shader: the key light's reflectance law (docs/model.md,
// section 8), applied to the source before the blur.
//
// A renderer applies it in its lighting pass: the key light's Lambertian
// diffuse term times invsssKeyLightLaw(normal, toLight), the function the
// exported constants file holds when the fit used the law (with lawAlbedo and
// lawStrength). This compute version does the same to an image already lit:
//
//   LawCS: source (all lights, Lambertian) -> source with the key light's part
//          under the law: S + mask * K * (invsssKeyLightLaw(n, l) - 1)
//
// with K the source lit by the key light alone (KeyLight). When the fit used the
// fill term the constants file defines INVSSS_OTHER_LIGHT_LAW and
// invsssOtherLightLaw, and LawCS also puts the other lights' part under the law:
// + mask * (S - K) * (invsssOtherLightLaw(n, l_f) - 1), l_f from FillToLight.
// Run the model's passes on its output. Build with glslangValidator -D -V -S comp -e LawCS,
// the exported `invsss_constants.hlsl` next to this file.

#include "invsss_constants.hlsl"
#include "invsss_common.hlsl"

[numthreads(8, 8, 1)]
void LawCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float3 normal = Normal.Load(int3(p, 0)).xyz;
    float3 toLight = ToLight.Load(int3(p, 0)).xyz;
    float4 source = Source.Load(int3(p, 0));
    float3 key = KeyLight.Load(int3(p, 0)).rgb;
    float mask = Mask.Load(int3(p, 0));
    float3 lit = source.rgb + mask * key * (invsssKeyLightLaw(normal, toLight) - 1.0);
#ifdef INVSSS_OTHER_LIGHT_LAW
    float3 toFill = FillToLight.Load(int3(p, 0)).xyz;
    lit += mask * (source.rgb - key) * (invsssOtherLightLaw(normal, toFill) - 1.0);
#endif
    Destination[p] = float4(lit, source.a);
}
