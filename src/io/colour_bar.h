// The scale under a false-colour slice picture: the ramp of falseColour (slice_export.h) over
// log2 f from log2Min (left) to log2Max (right), a tick at each decade of f it shows (every second,
// fifth … decade when the numbers would touch), the value of f written under each tick, and the
// unit (BSDF 1/SR) — so the picture can be read without the command line that made it.
#pragma once
#include "io/png_image.h"

namespace mbsdf {

// The height in pixels of the scale under a picture of height `size` (ramp, ticks and two text rows).
int colourBarHeight(int size);
// Draws the scale into rows [y0, y0 + colourBarHeight(size)) of img, over its whole width.
void drawColourBar(RgbImage& img, int y0, int size, double log2Min, double log2Max);

}  // namespace mbsdf
