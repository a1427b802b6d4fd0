// The parse_* functions of the optimizers' enums: the value whose name is `name`.
#pragma once

#include <optional>
#include <string_view>
#include <vector>

namespace bvhopt::detail {

template <class E, class NameOf>
std::optional<E> find_by_name(const std::vector<E>& all, NameOf name_of, std::string_view name) {
  for (E e : all)
    if (name_of(e) == name) return e;
  return std::nullopt;
}

}  // namespace bvhopt::detail
