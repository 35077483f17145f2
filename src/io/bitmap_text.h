// Labels in pictures (contact sheets, previews, colour bars) with a 5 x 7 bitmap font: digits, '.',
// '-', '+', '/', ' ', '°' and the capitals A B C D E F G I L M R S W Z — what model names, angles,
// the colour bar's numbers and unit and diff's labels need; no font file to find on a cluster node.
#pragma once
#include <cstdint>
#include <string>

#include "io/png_image.h"

namespace mbsdf {

// Draws `text` scaled by `scale` (each glyph 6·scale wide with its gap), top-left at (x, y), in
// grey level `grey`; what falls outside the image is clipped, unknown characters are left blank.
void drawText(RgbImage& img, int x, int y, const std::string& text, int scale, uint8_t grey);
// The width in pixels drawText gives `text`.
int textWidth(const std::string& text, int scale);

}  // namespace mbsdf
