#include "common/splat/sh.h"

#include <algorithm>

namespace instascene {

void EvalShColor(int degree, const float* coeffs, float x, float y, float z, float rgb[3]) {
  float basis[16];
  basis[0] = kShC0;
  int n = 1;
  if (degree >= 1) {
    basis[1] = -kShC1 * y;
    basis[2] = kShC1 * z;
    basis[3] = -kShC1 * x;
    n = 4;
  }
  if (degree >= 2) {
    const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    basis[4] = kShC2[0] * xy;
    basis[5] = kShC2[1] * yz;
    basis[6] = kShC2[2] * (2.0f * zz - xx - yy);
    basis[7] = kShC2[3] * xz;
    basis[8] = kShC2[4] * (xx - yy);
    n = 9;
    if (degree >= 3) {
      basis[9] = kShC3[0] * y * (3.0f * xx - yy);
      basis[10] = kShC3[1] * xy * z;
      basis[11] = kShC3[2] * y * (4.0f * zz - xx - yy);
      basis[12] = kShC3[3] * z * (2.0f * zz - 3.0f * xx - 3.0f * yy);
      basis[13] = kShC3[4] * x * (4.0f * zz - xx - yy);
      basis[14] = kShC3[5] * z * (xx - yy);
      basis[15] = kShC3[6] * x * (xx - 3.0f * yy);
      n = 16;
    }
  }
  for (int c = 0; c < 3; ++c) {
    float v = 0.5f;
    for (int k = 0; k < n; ++k) v += basis[k] * coeffs[k * 3 + c];
    rgb[c] = std::max(v, 0.0f);
  }
}

}  // namespace instascene
