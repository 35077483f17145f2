#include "io/bitmap_text.h"

#include <array>
#include <map>

namespace mbsdf {
namespace {

// 5 x 7 glyphs, one string per row ('#' = ink).
const std::map<std::string, std::array<const char*, 7>>& font() {
  static const std::map<std::string, std::array<const char*, 7>> f = {
      {"0", {" ### ", "#   #", "#  ##", "# # #", "##  #", "#   #", " ### "}},
      {"1", {"  #  ", " ##  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "}},
      {"2", {" ### ", "#   #", "    #", "   # ", "  #  ", " #   ", "#####"}},
      {"3", {"#####", "   # ", "  #  ", "   # ", "    #", "#   #", " ### "}},
      {"4", {"   # ", "  ## ", " # # ", "#  # ", "#####", "   # ", "   # "}},
      {"5", {"#####", "#    ", "#### ", "    #", "    #", "#   #", " ### "}},
      {"6", {"  ## ", " #   ", "#    ", "#### ", "#   #", "#   #", " ### "}},
      {"7", {"#####", "    #", "   # ", "  #  ", " #   ", " #   ", " #   "}},
      {"8", {" ### ", "#   #", "#   #", " ### ", "#   #", "#   #", " ### "}},
      {"9", {" ### ", "#   #", "#   #", " ####", "    #", "   # ", " ##  "}},
      {".", {"     ", "     ", "     ", "     ", "     ", " ##  ", " ##  "}},
      {"-", {"     ", "     ", "     ", "#####", "     ", "     ", "     "}},
      {"°", {" ##  ", "#  # ", "#  # ", " ##  ", "     ", "     ", "     "}},
      {"G", {" ### ", "#   #", "#    ", "# ###", "#   #", "#   #", " ####"}},
      {"S", {" ####", "#    ", "#    ", " ### ", "    #", "    #", "#### "}},
      {"M", {"#   #", "## ##", "# # #", "# # #", "#   #", "#   #", "#   #"}},
      {"W", {"#   #", "#   #", "#   #", "# # #", "# # #", "## ##", "#   #"}},
      {"C", {" ### ", "#   #", "#    ", "#    ", "#    ", "#   #", " ### "}},
      {"I", {" ### ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "}},
      {"L", {"#    ", "#    ", "#    ", "#    ", "#    ", "#    ", "#####"}},
      {"B", {"#### ", "#   #", "#   #", "#### ", "#   #", "#   #", "#### "}},
      {"D", {"#### ", "#   #", "#   #", "#   #", "#   #", "#   #", "#### "}},
      {"E", {"#####", "#    ", "#    ", "#### ", "#    ", "#    ", "#####"}},
      {"F", {"#####", "#    ", "#    ", "#### ", "#    ", "#    ", "#    "}},
      {"R", {"#### ", "#   #", "#   #", "#### ", "# #  ", "#  # ", "#   #"}},
      {"/", {"    #", "    #", "   # ", "  #  ", " #   ", "#    ", "#    "}},
      {"A", {" ### ", "#   #", "#   #", "#####", "#   #", "#   #", "#   #"}},
      {"Z", {"#####", "    #", "   # ", "  #  ", " #   ", "#    ", "#####"}},
      {"+", {"     ", "  #  ", "  #  ", "#####", "  #  ", "  #  ", "     "}},
      {" ", {"     ", "     ", "     ", "     ", "     ", "     ", "     "}},
  };
  return f;
}

}  // namespace

void drawText(RgbImage& img, int x, int y, const std::string& text, int scale, uint8_t grey) {
  int cx = x;
  for (size_t i = 0; i < text.size();) {
    // UTF-8 "°" is two bytes.
    std::string g = (uint8_t(text[i]) == 0xC2 && i + 1 < text.size()) ? text.substr(i, 2) : text.substr(i, 1);
    i += g.size();
    auto it = font().find(g);
    if (it != font().end())
      for (int r = 0; r < 7; ++r)
        for (int c = 0; c < 5; ++c)
          if (it->second[r][c] == '#')
            for (int dy = 0; dy < scale; ++dy)
              for (int dx = 0; dx < scale; ++dx) {
                const int px = cx + c * scale + dx, py = y + r * scale + dy;
                if (px < 0 || py < 0 || px >= img.width || py >= img.height) continue;
                for (int k = 0; k < 3; ++k) img.rgb[(size_t(py) * img.width + px) * 3 + k] = grey;
              }
    cx += 6 * scale;
  }
}

int textWidth(const std::string& text, int scale) {
  int glyphs = 0;
  for (size_t i = 0; i < text.size(); ++i)
    if (!(uint8_t(text[i]) == 0xC2 && i + 1 < text.size())) ++glyphs;  // "°" is two bytes, one glyph
  return glyphs * 6 * scale - scale;
}

}  // namespace mbsdf
