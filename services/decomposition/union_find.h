// services/decomposition/union_find.h: disjoint sets over 0..n-1 whose root is always the smallest
// member, so that components are numbered the same whatever order the unions come in (the mask
// clustering, DBSCAN's core cells and the instance merge rely on it for determinism).
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

namespace instascene::decomposition {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0u); }

  uint32_t Find(uint32_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];  // path halving
    return x;
  }
  // Joins the sets of a and b; false if they were one already.
  bool Union(uint32_t a, uint32_t b) {
    const uint32_t ra = Find(a), rb = Find(b);
    if (ra == rb) return false;
    parent_[std::max(ra, rb)] = std::min(ra, rb);
    return true;
  }
  // Per element, its set's number: the sets numbered 0, 1, ... in the order of their smallest
  // members, so an element whose number equals the count of sets seen so far (in index order)
  // is its set's first.
  std::vector<uint32_t> Components() {
    std::vector<uint32_t> out(parent_.size());
    uint32_t next = 0;
    for (uint32_t x = 0; x < parent_.size(); ++x) {
      const uint32_t root = Find(x);  // the smallest member: numbered before x unless x is it
      out[x] = root == x ? next++ : out[root];
    }
    return out;
  }

 private:
  std::vector<uint32_t> parent_;
};

}  // namespace instascene::decomposition
