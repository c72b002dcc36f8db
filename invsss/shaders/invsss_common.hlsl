// invsss reference shader: what every pass shares.
//
// This is the reference implementation of invsss's screen-space subsurface
// scattering (docs/model.md, sections 2, 3, 5 and 8; docs/renderer.md says how to
// use it). It is written as plain compute shaders so that a test can build it
// with glslangValidator and run it on Vulkan, and compare every pixel with
// `invsss render`. Porting it to Unity or Unreal means keeping exactly:
//
//   * the stretch factors: numpy.gradient's stencil on the linear eye depth
//     (central difference inside, one-sided at the first and last pixel);
//   * the sampling: pixel centres at integer coordinates, linear interpolation
//     between the two nearest pixels along the pass's axis, coordinates clamped
//     to [0, size - 1] (clamp-to-edge);
//   * the mask blend: out = centre + mask * (blurred - centre);
//   * the constants and their order, from `invsss export --format hlsl`.
//
// A bilinear SamplerState at uv = (pixel + 0.5) / size gives the same
// interpolation, but GPUs compute the interpolation weight with only 8 bits
// of sub-texel precision (Vulkan's minimum is 4), an error of up to 1/256 (1/16)
// of the difference between neighbours; this reference therefore interpolates by
// hand from two Load()s, which is exact in float32. Use SampleLevel in
// production if that error is acceptable for your content.
//
// Units: depth in the scene unit the fit used (mm for the bundled pairs), the
// profile in the same unit; sssLevel is in pixels of the image the fit saw
// (docs/renderer.md, "Another resolution").
//
// Registers: distinct numbers across t, u and b, so that glslang's default
// HLSL-to-Vulkan mapping (binding = register number, set 0) has no clashes.

#ifndef INVSSS_COMMON_HLSL
#define INVSSS_COMMON_HLSL

// Per dispatch: which pass this is (index into passWidths / blendFactors) and
// along which axis it blurs (0: along rows, horizontal; 1: along columns, vertical).
cbuffer InvsssPass : register(b0)
{
    uint passIndex;
    uint passAxis;
    uint2 invsssPassPadding;
};

Texture2D<float4> Source : register(t1);       // the pass's input (linear radiance, rgb; a is carried along)
Texture2D<float> Depth : register(t2);         // linear eye depth, > 0 on and next to the skin
Texture2D<float> Mask : register(t3);          // 1 on skin, 0 elsewhere; fractions blend
Texture2D<float4> Normal : register(t4);       // light terms: view-space unit normal in xyz (z towards the camera)
Texture2D<float4> ToLight : register(t5);      // light terms: view-space unit vector towards the key light in xyz
Texture2D<float4> KeyLight : register(t6);     // law term: the source lit by the key light alone
RWTexture2D<float4> Destination : register(u7); // the pass's output (read and written by AccumulateCS)
Texture2D<float4> FillToLight : register(t8);  // fill term: view-space unit vector towards the other lights in xyz
Texture2D<float> Thickness : register(t9);     // transmission term: mm the key light crosses inside the skin
Texture2D<float4> KeyIrradiance : register(t10); // transmission term: albedo times the key light's unshadowed irradiance

int2 InvsssSize()
{
    uint width, height;
    Depth.GetDimensions(width, height);
    return int2(width, height);
}

float InvsssDepthAt(int2 p)
{
    return Depth.Load(int3(p, 0));
}

// |d depth / d axis| at pixel p with numpy.gradient's stencil:
// (d[x+1] - d[x-1]) / 2 inside, d[1] - d[0] and d[n-1] - d[n-2] at the borders.
// Do not use ddx()/ddy() (2x2-quad differences) nor a one-sided difference
// everywhere: the fit measured sssLevel, correction and maxdd with this stencil.
float InvsssDepthSlope(int2 p, uint axis)
{
    int2 size = InvsssSize();
    int n = axis == 0 ? size.x : size.y;
    int c = axis == 0 ? p.x : p.y;
    int2 step = axis == 0 ? int2(1, 0) : int2(0, 1);
    int2 lo = c > 0 ? p - step : p;
    int2 hi = c < n - 1 ? p + step : p;
    int span = (c > 0 ? 1 : 0) + (c < n - 1 ? 1 : 0);
    if (span == 0)
        return 0.0;
    return abs((InvsssDepthAt(hi) - InvsssDepthAt(lo)) / float(span));
}

// Jimenez's stretch factor along one axis (docs/model.md, section 2), in pixels
// per scene unit: s = sssLevel / (depth + correction * min(|slope|, maxdd)).
float InvsssStretch(int2 p, uint axis)
{
    return sssLevel / (InvsssDepthAt(p) + correction * min(InvsssDepthSlope(p, axis), maxdd));
}

// Source read at the real coordinate u along the axis through pixel p (the
// other coordinate is p's own): linear interpolation, clamp-to-edge. The lower
// pixel stops one short of the edge so that the upper one exists (the fraction
// is then 1 at the last pixel), as invsss.passes.sample_along does.
float4 InvsssSampleAlong(int2 p, uint axis, float u)
{
    int2 size = InvsssSize();
    int n = axis == 0 ? size.x : size.y;
    u = clamp(u, 0.0, float(n - 1));
    int i0 = clamp(int(floor(u)), 0, max(n - 2, 0));
    int i1 = min(i0 + 1, n - 1);
    float frac = u - float(i0);
    int2 a = axis == 0 ? int2(i0, p.y) : int2(p.x, i0);
    int2 b = axis == 0 ? int2(i1, p.y) : int2(p.x, i1);
    float4 left = Source.Load(int3(a, 0));
    float4 right = Source.Load(int3(b, 0));
    return left + frac * (right - left);
}

// Source read at the real position q = (x, y): bilinear, clamp-to-edge (the
// shift term's read; invsss.light_terms.shift_image).
float4 InvsssSampleBilinear(float2 q)
{
    int2 size = InvsssSize();
    q = clamp(q, float2(0.0, 0.0), float2(size - 1));
    int2 c0 = clamp(int2(floor(q)), int2(0, 0), max(size - 2, int2(0, 0)));
    int2 c1 = min(c0 + 1, size - 1);
    float2 f = q - float2(c0);
    float4 top = Source.Load(int3(c0.x, c0.y, 0));
    top = top + f.x * (Source.Load(int3(c1.x, c0.y, 0)) - top);
    float4 bottom = Source.Load(int3(c0.x, c1.y, 0));
    bottom = bottom + f.x * (Source.Load(int3(c1.x, c1.y, 0)) - bottom);
    return top + f.y * (bottom - top);
}

// Off-mask pixels come out bit for bit unchanged: centre + 0 * (...) = centre.
float4 InvsssMaskBlend(int2 p, float4 centre, float4 result)
{
    return centre + Mask.Load(int3(p, 0)) * (result - centre);
}

bool InvsssOutside(uint3 id)
{
    int2 size = InvsssSize();
    return int(id.x) >= size.x || int(id.y) >= size.y;
}

#endif // INVSSS_COMMON_HLSL
