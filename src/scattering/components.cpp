#include "scattering/components.h"

namespace mbsdf {

std::optional<Component> componentFromName(const std::string& name) {
  for (int i = 0; i < kComponentCount; ++i)
    if (name == kComponentNames[i]) return Component(i);
  return std::nullopt;
}

std::optional<std::vector<Component>> modelComponents(const std::string& model) {
  if (model == "GS") return std::vector<Component>{Component::Coherent};
  if (model == "GM") return std::vector<Component>{Component::Coherent, Component::Multiple};
  if (model == "WS") return std::vector<Component>{Component::Coherent, Component::Incoherent};
  if (model == "WM") return std::vector<Component>{Component::Coherent, Component::Incoherent, Component::Multiple};
  if (auto c = componentFromName(model)) return std::vector<Component>{*c};
  return std::nullopt;
}

}  // namespace mbsdf
