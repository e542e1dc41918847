// common/fmbd_svg.h: a small SVG line-plot writer (several series, linear or log axes)
// SPDX-License-Identifier: MIT
//
// Used by cbcheck --plot (estimates vs exact error, convergence in Nd), fmbd-run
// (trajectories) and the benchmarks (error vs time). One plot per file: axes with ticks and
// labels (decades on log axes), a legend, lines and/or markers per series. Points that cannot
// be drawn (NaN, or <= 0 on a log axis) are skipped and break the line. The file is written
// to "<path>.part" and renamed when complete.
#ifndef FMBD_SVG_H
#define FMBD_SVG_H

#include <stdbool.h>
#include <stdint.h>

enum fmbd_svg_marker {
  FMBD_SVG_NONE = 0,
  FMBD_SVG_CIRCLE,
  FMBD_SVG_SQUARE,
  FMBD_SVG_TRIANGLE,
  FMBD_SVG_CROSS,
  FMBD_SVG_DIAMOND
};
enum fmbd_svg_line { FMBD_SVG_SOLID = 0, FMBD_SVG_NOLINE, FMBD_SVG_DASHED, FMBD_SVG_DOTTED };

/// One series: n points (x[i], y[i]) (borrowed arrays).
typedef struct fmbd_svg_series {
  const char *label;    ///< legend text (NULL or "": not in the legend)
  int64_t n;            ///< number of points
  const double *x, *y;  ///< n values each
  const char *color;    ///< CSS colour ("#1f77b4"); NULL: the next of a 10-colour cycle
  int marker;           ///< enum fmbd_svg_marker (default FMBD_SVG_NONE)
  int line;             ///< enum fmbd_svg_line (default FMBD_SVG_SOLID)
} fmbd_svg_series;

/// The axes and frame. Fill with fmbd_svg_plot_defaults, then set what you need.
typedef struct fmbd_svg_plot {
  const char *title;   ///< above the plot (NULL: none)
  const char *xlabel;  ///< below the x axis (NULL: none)
  const char *ylabel;  ///< left of the y axis, rotated (NULL: none)
  bool xlog, ylog;     ///< logarithmic axes (default false)
  double xmin, xmax;   ///< axis range; NaN (default): from the data, rounded outward
  double ymin, ymax;
  int width_px, height_px;  ///< image size (default 720 x 480)
  int legend;               ///< 0 none, 1 top right, 2 top left, 3 bottom right, 4 bottom left,
                            ///< 5 (default) the corner covering the fewest data points
} fmbd_svg_plot;

/// @brief Defaults: no titles, linear axes, automatic ranges, 720 x 480, legend in the corner
/// that covers the fewest data points.
void fmbd_svg_plot_defaults(fmbd_svg_plot *p);

/// @brief Write the plot to path (atomically through "<path>.part").
/// @param[in] p        the axes (borrowed)
/// @param[in] nseries  number of series (0 gives empty axes)
/// @param[in] s        the series (borrowed)
/// @return FMBD_OK, FMBD_ERR_IO (cannot write; the message names path), FMBD_ERR_VALUE
///         (no drawable point on a log axis and no range given, or a bad range)
int fmbd_svg_write(const char *path, const fmbd_svg_plot *p, int nseries, const fmbd_svg_series *s);

#endif
