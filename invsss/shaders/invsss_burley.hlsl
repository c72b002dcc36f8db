// invsss reference shader, model `burley` (docs/model.md, section 5): Christensen
// and Burley's normalized diffusion gathered over a disk around each skin pixel,
// the blur Unity HDRP and Unreal Engine ship, with invsss's fixed sample pattern.
//
// Build BurleyDiskCS (glslangValidator -D -V -S comp -e BurleyDiskCS) with the
// constants of a burley fit (`invsss export params.json --format hlsl`) saved as
// `invsss_constants.hlsl` next to this file, and run it once:
//
//   BurleyDiskCS: image -> out          (passIndex and passAxis are not used)
//
// For pixel p on the skin, sample j (0 .. numSamples - 1) lies at
//
//   r_j   = dMax * sampleRadii[j]                               scene units
//   q_j   = p + r_j * sssLevel / depth(p) * (sampleCos[j], sampleSin[j])   pixels
//
// with dMax the largest of shapeParameters (Burley's d per channel, scene
// units; one value serves every channel). The radii are the quantiles
// (j + 1/2) / numSamples of the widest channel's radial distribution, the
// directions turn by the golden angle: use the exported numbers, do not make
// up another pattern, jitter it or rotate it per pixel. Image, mask and depth
// are read at q_j with bilinear interpolation and clamp-to-edge (pixel centres
// at integer coordinates), and channel c weights the sample by
//
//   w_jc = (e^(-rho/d_c) + e^(-rho/(3 d_c))) / d_c
//        / ((e^(-r_j/dMax) + e^(-r_j/(3 dMax))) / dMax) * mask(q_j),
//   rho  = sqrt(r_j^2 + (depth(q_j) - depth(p))^2),
//
// the profile at the 3D distance between the two surface points (times rho)
// over the pdf the radii were drawn from. The result is sum_j w_jc I(q_j) /
// sum_j w_jc per channel (the blur keeps energy); a channel whose weights are
// all 0 (every sample off the skin) keeps the pixel's value, and the mask
// blends: out = I + mask(p) * (blurred - I). Off the mask (mask 0) the pixel is
// copied without any sample being read. correction and maxdd are not used: this
// model projects with sssLevel / depth only, no slope term.
//
// Cost per skin pixel: numSamples samples of 4 image, 4 mask and 4 depth reads
// (bilinear by hand; a sampler would do each in one, see invsss_common.hlsl on
// its precision), plus the image, mask and depth at the centre: 387 reads for
// the 32 samples; off the skin 2 (the mask and the image).

#include "invsss_constants.hlsl"
#include "invsss_common.hlsl"

// Burley's d of channel c (red, green, blue); a grey fit exports one d.
float InvsssShapeParameter(int c)
{
    return shapeParameters[min(c, numShapeParameters - 1)];
}

// What one sample reads: the source, the mask and the depth at the same point.
struct InvsssDiskRead
{
    float4 value;
    float mask;
    float depth;
};

// Source, Mask and Depth at the real position q = (x, y): bilinear with
// clamp-to-edge, the four corners shared (invsss.forward.burley_screen_space's
// sample_bilinear): along x first, then along y.
InvsssDiskRead InvsssReadDisk(float2 q)
{
    int2 size = InvsssSize();
    q = clamp(q, float2(0.0, 0.0), float2(size - 1));
    int2 c0 = clamp(int2(floor(q)), int2(0, 0), max(size - 2, int2(0, 0)));
    int2 c1 = min(c0 + 1, size - 1);
    float2 f = q - float2(c0);
    int3 corner[4] = { int3(c0.x, c0.y, 0), int3(c1.x, c0.y, 0), int3(c0.x, c1.y, 0), int3(c1.x, c1.y, 0) };

    float4 v[4];
    float m[4];
    float z[4];
    [unroll]
    for (int k = 0; k < 4; ++k)
    {
        v[k] = Source.Load(corner[k]);
        m[k] = Mask.Load(corner[k]);
        z[k] = Depth.Load(corner[k]);
    }
    InvsssDiskRead read;
    float4 vTop = v[0] + f.x * (v[1] - v[0]);
    float4 vBottom = v[2] + f.x * (v[3] - v[2]);
    read.value = vTop + f.y * (vBottom - vTop);
    float mTop = m[0] + f.x * (m[1] - m[0]);
    float mBottom = m[2] + f.x * (m[3] - m[2]);
    read.mask = mTop + f.y * (mBottom - mTop);
    float zTop = z[0] + f.x * (z[1] - z[0]);
    float zBottom = z[2] + f.x * (z[3] - z[2]);
    read.depth = zTop + f.y * (zBottom - zTop);
    return read;
}

[numthreads(8, 8, 1)]
void BurleyDiskCS(uint3 id : SV_DispatchThreadID)
{
    if (InvsssOutside(id))
        return;
    int2 p = int2(id.xy);
    float4 centre = Source.Load(int3(p, 0));
    if (Mask.Load(int3(p, 0)) == 0.0)
    {
        Destination[p] = centre;   // off the skin: unchanged, as the mask blend gives
        return;
    }
    float3 d = float3(InvsssShapeParameter(0), InvsssShapeParameter(1), InvsssShapeParameter(2));
    float dMax = max(d.x, max(d.y, d.z));
    float z = InvsssDepthAt(p);
    float scale = sssLevel / z;   // pixels per scene unit at this pixel

    float3 total = float3(0.0, 0.0, 0.0);
    float3 weightSum = float3(0.0, 0.0, 0.0);
    for (int j = 0; j < numSamples; ++j)
    {
        float r = dMax * sampleRadii[j];
        float radiusPx = r * scale;
        InvsssDiskRead s = InvsssReadDisk(float2(p) + radiusPx * float2(sampleCos[j], sampleSin[j]));
        float dz = s.depth - z;
        float rho = sqrt(r * r + dz * dz);
        float3 profile = (exp(-rho / d) + exp(-rho / (3.0 * d))) / d;
        float pdf = (exp(-r / dMax) + exp(-r / (3.0 * dMax))) / dMax;
        float3 weight = profile / pdf * s.mask;
        total += weight * s.value.rgb;
        weightSum += weight;
    }

    float3 blurred = centre.rgb;
    [unroll]
    for (int c = 0; c < 3; ++c)
    {
        if (weightSum[c] > 0.0)
            blurred[c] = total[c] / weightSum[c];
    }
    Destination[p] = InvsssMaskBlend(p, centre, float4(blurred, centre.a));
}
