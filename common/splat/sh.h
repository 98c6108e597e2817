// common/splat/sh.h: real spherical-harmonics colour evaluation (degree 0-3), as in the Inria and
// 2DGS rasterizers (ALGORITHM.md 2.7). Stateless, thread-safe.
#pragma once

namespace instascene {

inline constexpr float kShC0 = 0.28209479177387814f;
inline constexpr float kShC1 = 0.4886025119029199f;
inline constexpr float kShC2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                                   -1.0925484305920792f, 0.5462742152960396f};
inline constexpr float kShC3[7] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                                   0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                                   -0.5900435899266435f};

// RGB of SH coefficients `coeffs` ([coeff][rgb], NumShCoeffs(degree) * 3 floats) seen along the
// unit direction (x, y, z) from the camera centre to the Gaussian; +0.5 then clamped at >= 0 only.
void EvalShColor(int degree, const float* coeffs, float x, float y, float z, float rgb[3]);

// Degree-0 coefficient for a colour: (rgb - 0.5) / C0.
inline float RgbToSh0(float value) { return (value - 0.5f) / kShC0; }

}  // namespace instascene
