// The std::visit helper for closed sets of value types (std::variant): a lambda per alternative.
#pragma once

namespace mbsdf {

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

}  // namespace mbsdf
