// The components of the tabulated BSDF (docs/physics.md §3). The paper's models are sums:
// GS = coherent, GM = coherent + multiple, WS = coherent + incoherent,
// WM = coherent + incoherent + multiple.
#pragma once
#include <array>
#include <optional>
#include <string>
#include <vector>

namespace mbsdf {

enum class Component : int { Coherent = 0, Incoherent = 1, Multiple = 2, Lost = 3, GeoMasked = 4 };
inline constexpr int kComponentCount = 5;
inline constexpr std::array<const char*, kComponentCount> kComponentNames = {"coherent", "incoherent", "multiple",
                                                                             "lost", "geo_masked"};

inline const char* componentName(Component c) {
  return kComponentNames[int(c)];
}
// Whether the component is reciprocal in reflection, f(i → o) = f(o → i) (docs/physics.md §8):
// coherent, incoherent and multiple. Not lost (the masked power is not reciprocal) nor geo_masked.
inline bool isReciprocal(Component c) {
  return c == Component::Coherent || c == Component::Incoherent || c == Component::Multiple;
}
std::optional<Component> componentFromName(const std::string& name);

// Which components a model sums ("GS", "GM", "WS", "WM", or a single component name).
std::optional<std::vector<Component>> modelComponents(const std::string& model);

struct ComponentSet {
  unsigned bits = 0;
  bool has(Component c) const { return bits & (1u << int(c)); }
  void add(Component c) { bits |= 1u << int(c); }
  void remove(Component c) { bits &= ~(1u << int(c)); }
  std::vector<Component> list() const {
    std::vector<Component> v;
    for (int i = 0; i < kComponentCount; ++i)
      if (bits & (1u << i)) v.push_back(Component(i));
    return v;
  }
};

}  // namespace mbsdf
