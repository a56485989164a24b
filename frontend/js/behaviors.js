// Behaviour colours: the same table as app/viewer/palette.py BEHAVIOR_COLORS (a test keeps them equal),
// so the status panel and the 3D view's ring, label and recovery markers agree.
export const BEHAVIOR_COLORS = {
  compute_path: [40, 120, 255],
  follow_path: [0, 200, 120],
  blocked: [230, 50, 50],
  clear_local_costmap: [0, 200, 230],
  clear_global_costmap: [0, 140, 200],
  clear_costmaps: [0, 170, 215],
  spin: [170, 80, 255],
  spin_until_matched: [230, 60, 200],
  relocalize: [255, 60, 120],
  wait: [255, 200, 0],
  wait_for_walker: [255, 225, 120],
  back_up: [255, 120, 0],
  drive_on_heading: [180, 220, 40],
};
export const UNKNOWN_BEHAVIOR = [170, 170, 170];

/** CSS colour of a behaviour name (grey for one not in the table). */
export function behaviorColor(name) {
  const [r, g, b] = BEHAVIOR_COLORS[name] || UNKNOWN_BEHAVIOR;
  return `rgb(${r}, ${g}, ${b})`;
}
