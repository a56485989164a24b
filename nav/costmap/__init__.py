"""Layered costmaps (Nav2 ``nav2_costmap_2d``): static, obstacle and inflation layers, a global
map-sized costmap and a local rolling window, and vectorized footprint costs."""

from nav.costmap.costmap2d import (
    Costmap2D,
    CostmapError,
    CostmapOptions,
    LayeredCostmap,
    local_costmap_options,
)
from nav.costmap.footprint import circle_footprint, footprint_cost, footprint_radii
from nav.costmap.inflation import InflationOptions, inflate, inflation_cost
from nav.costmap.obstacle_layer import ObstacleLayer, ObstacleLayerOptions
from nav.costmap.static_layer import StaticLayerOptions, static_costs

__all__ = [
    "Costmap2D",
    "CostmapError",
    "CostmapOptions",
    "InflationOptions",
    "LayeredCostmap",
    "ObstacleLayer",
    "ObstacleLayerOptions",
    "StaticLayerOptions",
    "circle_footprint",
    "footprint_cost",
    "footprint_radii",
    "inflate",
    "inflation_cost",
    "local_costmap_options",
    "static_costs",
]
