// fogbeam — the "overloaded" visitor for std::visit over a std::variant: a lambda per
// alternative. The explicit deduction guide is for clang < 17, which lacks C++20's class template
// argument deduction for aggregates (P1816); GCC does not need it.
#pragma once

namespace fogbeam {

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

}  // namespace fogbeam
