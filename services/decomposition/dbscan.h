// services/decomposition/dbscan.h: DBSCAN over 3D points, grid accelerated (the post-processing's
// spatial split of each cluster, ALGORITHM.md 4.7).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace instascene::decomposition {

// DBSCAN over points (Open3D semantics: min_points counts the point itself; -1 = noise), grid
// accelerated. Clusters are numbered in order of their first core point by index; border points
// join the cluster of their nearest core point.
std::vector<int> Dbscan(const std::vector<Eigen::Vector3f>& points, float eps, int min_points);

}  // namespace instascene::decomposition
