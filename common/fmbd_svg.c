// common/fmbd_svg.c: a small SVG line-plot writer
// SPDX-License-Identifier: MIT
#include "fmbd_svg.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"

static const char *const palette[10] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                        "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};

void fmbd_svg_plot_defaults(fmbd_svg_plot *p) {
  memset(p, 0, sizeof(*p));
  p->xmin = p->xmax = p->ymin = p->ymax = NAN;
  p->width_px = 720;
  p->height_px = 480;
  p->legend = 5;
}

// one axis: data range -> pixel map, with ticks
typedef struct axis {
  bool log;
  double lo, hi;  // in data units (log: positive)
  double p0, p1;  // pixels of lo and hi
} axis;

static double amap(const axis *a, double v) {
  double t = a->log ? (log10(v) - log10(a->lo)) / (log10(a->hi) - log10(a->lo))
                    : (v - a->lo) / (a->hi - a->lo);
  return a->p0 + t * (a->p1 - a->p0);
}

static bool drawable(const axis *a, double v) {
  return isfinite(v) && (!a->log || v > 0);
}

// "nice" step for a linear axis: 1, 2 or 5 times a power of ten giving ~n ticks
static double nice_step(double span, int n) {
  double raw = span / n, p = pow(10, floor(log10(raw))), f = raw / p;
  return (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * p;
}

static int set_range(axis *a, double dmin, double dmax, double umin, double umax,
                     const char *name) {
  double lo = isnan(umin) ? dmin : umin, hi = isnan(umax) ? dmax : umax;
  if (!isfinite(lo) || !isfinite(hi)) {
    if (a->log) {
      FMBD_FAIL(FMBD_ERR_VALUE, "%s axis: no positive value to plot on a log axis", name);
    }
    lo = 0;
    hi = 1;
  }
  if (isnan(umin) && isfinite(lo) && isfinite(hi) && lo > hi) {  // data above a given max
    lo = a->log ? hi / 1000 : hi - 1;
  }
  if (isnan(umax) && isfinite(lo) && isfinite(hi) && lo > hi) {  // data below a given min
    hi = a->log ? lo * 1000 : lo + 1;
  }
  if (a->log && (lo <= 0 || hi <= 0)) {
    FMBD_FAIL(FMBD_ERR_VALUE, "%s axis: log range [%g, %g] not positive", name, lo, hi);
  }
  if (hi < lo) {
    FMBD_FAIL(FMBD_ERR_VALUE, "%s axis: range [%g, %g] reversed", name, lo, hi);
  }
  if (a->log) {
    if (isnan(umin)) {
      lo = pow(10, floor(log10(lo) + 1e-9));
    }
    if (isnan(umax)) {
      hi = pow(10, ceil(log10(hi) - 1e-9));
    }
    if (hi <= lo) {
      hi = lo * 10;
    }
  } else {
    if (hi == lo) {
      double d = lo == 0 ? 1 : fabs(lo) * 0.1;
      lo -= d;
      hi += d;
    }
    double st = nice_step(hi - lo, 6);
    if (isnan(umin)) {
      lo = floor(lo / st + 1e-9) * st;
    }
    if (isnan(umax)) {
      hi = ceil(hi / st - 1e-9) * st;
    }
  }
  a->lo = lo;
  a->hi = hi;
  return FMBD_OK;
}

static void xml_text(FILE *fp, const char *s) {
  for (; s && *s; s++) {
    switch (*s) {
      case '<':
        fputs("&lt;", fp);
        break;
      case '>':
        fputs("&gt;", fp);
        break;
      case '&':
        fputs("&amp;", fp);
        break;
      case '"':
        fputs("&quot;", fp);
        break;
      default:
        fputc(*s, fp);
    }
  }
}

static void tick_label(char *buf, size_t n, double v, bool log) {
  if (log) {
    int e = (int)lround(log10(v));
    if (e >= -2 && e <= 3) {
      snprintf(buf, n, "%g", pow(10, e));
    } else {
      snprintf(buf, n, "1e%d", e);
    }
  } else {
    if (fabs(v) < 1e-12) {
      v = 0;
    }
    snprintf(buf, n, "%g", v);
  }
}

static void draw_ticks(FILE *fp, const axis *a, bool is_x, double other0, double other1) {
  char buf[64];
  if (a->log) {
    int e0 = (int)floor(log10(a->lo) + 1e-9), e1 = (int)ceil(log10(a->hi) - 1e-9);
    int every = (e1 - e0 > 12) ? (e1 - e0 + 11) / 12 : 1;
    for (int e = e0; e <= e1; e++) {
      for (int m = 1; m <= 9; m++) {
        double v = m * pow(10, e);
        if (v < a->lo * (1 - 1e-9) || v > a->hi * (1 + 1e-9)) {
          continue;
        }
        double p = amap(a, v);
        bool major = m == 1 && (e - e0) % every == 0;
        if (m != 1 && e1 - e0 > 8) {
          continue;
        }
        if (is_x) {
          fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n", p,
                  other0, p, other1, major ? "#dddddd" : "#f2f2f2");
          fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>\n",
                  p, other0, p, other0 + (major ? 6 : 3));
          if (major) {
            tick_label(buf, sizeof buf, v, true);
            fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n", p,
                    other0 + 20, buf);
          }
        } else {
          fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n",
                  other0, p, other1, p, major ? "#dddddd" : "#f2f2f2");
          fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>\n",
                  other0, p, other0 - (major ? 6 : 3), p);
          if (major) {
            tick_label(buf, sizeof buf, v, true);
            fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%s</text>\n", other0 - 9,
                    p + 4, buf);
          }
        }
      }
    }
  } else {
    double st = nice_step(a->hi - a->lo, 6);
    double v0 = ceil(a->lo / st - 1e-9) * st;
    for (int i = 0; i < 100; i++) {
      double v = v0 + i * st;
      if (v > a->hi + 1e-9 * st) {
        break;
      }
      double p = amap(a, v);
      tick_label(buf, sizeof buf, v, false);
      if (is_x) {
        fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#dddddd\"/>\n",
                p, other0, p, other1);
        fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n", p,
                other0 + 20, buf);
      } else {
        fprintf(fp, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#dddddd\"/>\n",
                other0, p, other1, p);
        fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%s</text>\n", other0 - 9,
                p + 4, buf);
      }
    }
  }
}

static void marker(FILE *fp, int kind, double x, double y, const char *c) {
  const double r = 3.5;
  switch (kind) {
    case FMBD_SVG_CIRCLE:
      fprintf(fp, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" fill=\"none\" stroke=\"%s\"/>\n", x,
              y, r, c);
      break;
    case FMBD_SVG_SQUARE:
      fprintf(fp,
              "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" "
              "stroke=\"%s\"/>\n",
              x - r, y - r, 2 * r, 2 * r, c);
      break;
    case FMBD_SVG_TRIANGLE:
      fprintf(fp, "<path d=\"M%.1f %.1fL%.1f %.1fL%.1f %.1fZ\" fill=\"none\" stroke=\"%s\"/>\n", x,
              y - r, x + r, y + r, x - r, y + r, c);
      break;
    case FMBD_SVG_CROSS:
      fprintf(fp, "<path d=\"M%.1f %.1fL%.1f %.1fM%.1f %.1fL%.1f %.1f\" stroke=\"%s\"/>\n", x - r,
              y - r, x + r, y + r, x - r, y + r, x + r, y - r, c);
      break;
    case FMBD_SVG_DIAMOND:
      fprintf(fp,
              "<path d=\"M%.1f %.1fL%.1f %.1fL%.1f %.1fL%.1f %.1fZ\" fill=\"none\" "
              "stroke=\"%s\"/>\n",
              x, y - r, x + r, y, x, y + r, x - r, y, c);
      break;
    default:
      break;
  }
}

int fmbd_svg_write(const char *path, const fmbd_svg_plot *p, int nseries,
                   const fmbd_svg_series *s) {
  int rc = FMBD_OK;
  FILE *fp = NULL;
  char *tmp = NULL;
  axis ax = {.log = p->xlog}, ay = {.log = p->ylog};
  // --- data ranges --------------------------------------------------------------------------
  double xmn = INFINITY, xmx = -INFINITY, ymn = INFINITY, ymx = -INFINITY;
  for (int k = 0; k < nseries; k++) {
    for (int64_t i = 0; i < s[k].n; i++) {
      if (drawable(&ax, s[k].x[i]) && drawable(&ay, s[k].y[i])) {
        xmn = fmin(xmn, s[k].x[i]);
        xmx = fmax(xmx, s[k].x[i]);
        ymn = fmin(ymn, s[k].y[i]);
        ymx = fmax(ymx, s[k].y[i]);
      }
    }
  }
  fmbd_err_context(path, "");
  FMBD_GCALL(set_range(&ax, xmn, xmx, p->xmin, p->xmax, "x"));
  FMBD_GCALL(set_range(&ay, ymn, ymx, p->ymin, p->ymax, "y"));
  int W = p->width_px > 100 ? p->width_px : 720, H = p->height_px > 100 ? p->height_px : 480;
  double left = 80, right = W - 20, top = p->title ? 40 : 20, bottom = H - 55;
  ax.p0 = left;
  ax.p1 = right;
  ay.p0 = bottom;
  ay.p1 = top;
  // --- write ----------------------------------------------------------------------------------
  size_t n = strlen(path) + 6;
  FMBD_GALLOC(tmp = fmbd_malloc(n));
  snprintf(tmp, n, "%s.part", path);
  fp = fopen(tmp, "w");
  FMBD_GCHECK(fp, FMBD_ERR_IO, "cannot write %s: %s", tmp, strerror(errno));
  fprintf(fp,
          "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" "
          "width=\"%d\" height=\"%d\" viewBox=\"0 0 %d %d\" font-family=\"sans-serif\" "
          "font-size=\"12\">\n<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n",
          W, H, W, H);
  if (p->title) {
    fprintf(fp, "<text x=\"%.1f\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">",
            (left + right) / 2);
    xml_text(fp, p->title);
    fputs("</text>\n", fp);
  }
  draw_ticks(fp, &ax, true, bottom, top);
  draw_ticks(fp, &ay, false, left, right);
  fprintf(fp,
          "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" "
          "stroke=\"black\"/>\n",
          left, top, right - left, bottom - top);
  if (p->xlabel) {
    fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">", (left + right) / 2,
            bottom + 42.0);
    xml_text(fp, p->xlabel);
    fputs("</text>\n", fp);
  }
  if (p->ylabel) {
    fprintf(fp, "<text transform=\"translate(18 %.1f) rotate(-90)\" text-anchor=\"middle\">",
            (top + bottom) / 2);
    xml_text(fp, p->ylabel);
    fputs("</text>\n", fp);
  }
  fprintf(fp,
          "<clipPath id=\"plotarea\"><rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" "
          "height=\"%.1f\"/></clipPath>\n",
          left, top, right - left, bottom - top);
  for (int k = 0; k < nseries; k++) {
    const char *c = s[k].color ? s[k].color : palette[k % 10];
    const char *dash = s[k].line == FMBD_SVG_DASHED   ? " stroke-dasharray=\"6 4\""
                       : s[k].line == FMBD_SVG_DOTTED ? " stroke-dasharray=\"2 3\""
                                                      : "";
    fputs("<g clip-path=\"url(#plotarea)\">\n", fp);
    if (s[k].line != FMBD_SVG_NOLINE) {
      bool open = false;
      for (int64_t i = 0; i < s[k].n; i++) {
        if (!drawable(&ax, s[k].x[i]) || !drawable(&ay, s[k].y[i])) {
          if (open) {
            fputs("\"/>\n", fp);
          }
          open = false;
          continue;
        }
        if (!open) {
          fprintf(fp, "<path fill=\"none\" stroke=\"%s\" stroke-width=\"1.5\"%s d=\"M", c, dash);
          open = true;
        } else {
          fputc('L', fp);
        }
        fprintf(fp, "%.1f %.1f", amap(&ax, s[k].x[i]), amap(&ay, s[k].y[i]));
      }
      if (open) {
        fputs("\"/>\n", fp);
      }
    }
    if (s[k].marker != FMBD_SVG_NONE) {
      for (int64_t i = 0; i < s[k].n; i++) {
        if (drawable(&ax, s[k].x[i]) && drawable(&ay, s[k].y[i])) {
          marker(fp, s[k].marker, amap(&ax, s[k].x[i]), amap(&ay, s[k].y[i]), c);
        }
      }
    }
    fputs("</g>\n", fp);
  }
  // --- legend ---------------------------------------------------------------------------------
  int nl = 0;
  for (int k = 0; k < nseries; k++) {
    nl += s[k].label && s[k].label[0];
  }
  if (p->legend && nl > 0) {
    double lw = 0;
    for (int k = 0; k < nseries; k++) {
      if (s[k].label) {
        lw = fmax(lw, 7.0 * (double)strlen(s[k].label));
      }
    }
    lw += 50;
    double lh = 18.0 * nl + 8;
    int corner = p->legend;
    if (corner < 1 || corner > 4) {
      // automatic: the corner whose legend box would cover the fewest data points
      int best = 1;
      int64_t fewest = -1;
      for (int cand = 1; cand <= 4; cand++) {
        double cx = (cand == 2 || cand == 4) ? left + 10 : right - lw - 10;
        double cy = (cand >= 3) ? bottom - lh - 10 : top + 10;
        int64_t covered = 0;
        for (int k = 0; k < nseries; k++) {
          for (int64_t i = 0; i < s[k].n; i++) {
            if (!drawable(&ax, s[k].x[i]) || !drawable(&ay, s[k].y[i])) {
              continue;
            }
            double px = amap(&ax, s[k].x[i]), py = amap(&ay, s[k].y[i]);
            covered += px >= cx - 4 && px <= cx + lw + 4 && py >= cy - 4 && py <= cy + lh + 4;
          }
        }
        if (fewest < 0 || covered < fewest) {
          fewest = covered;
          best = cand;
        }
      }
      corner = best;
    }
    double lx = (corner == 2 || corner == 4) ? left + 10 : right - lw - 10;
    double ly = (corner >= 3) ? bottom - lh - 10 : top + 10;
    fprintf(fp,
            "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" "
            "fill-opacity=\"0.85\" stroke=\"#999999\"/>\n",
            lx, ly, lw, lh);
    int row = 0;
    for (int k = 0; k < nseries; k++) {
      if (!s[k].label || !s[k].label[0]) {
        continue;
      }
      const char *c = s[k].color ? s[k].color : palette[k % 10];
      double yy = ly + 14 + 18.0 * row++;
      if (s[k].line != FMBD_SVG_NOLINE) {
        fprintf(fp,
                "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" "
                "stroke-width=\"1.5\"%s/>\n",
                lx + 8, yy - 4, lx + 36, yy - 4, c,
                s[k].line == FMBD_SVG_DASHED   ? " stroke-dasharray=\"6 4\""
                : s[k].line == FMBD_SVG_DOTTED ? " stroke-dasharray=\"2 3\""
                                               : "");
      }
      marker(fp, s[k].marker, lx + 22, yy - 4, c);
      fprintf(fp, "<text x=\"%.1f\" y=\"%.1f\">", lx + 42, yy);
      xml_text(fp, s[k].label);
      fputs("</text>\n", fp);
    }
  }
  fputs("</svg>\n", fp);
  FMBD_GCHECK(!ferror(fp), FMBD_ERR_IO, "write error on %s", tmp);
  int cr = fclose(fp);
  fp = NULL;
  FMBD_GCHECK(cr == 0, FMBD_ERR_IO, "cannot close %s: %s", tmp, strerror(errno));
  FMBD_GCHECK(rename(tmp, path) == 0, FMBD_ERR_IO, "cannot rename %s to %s: %s", tmp, path,
              strerror(errno));
done:
  if (fp) {
    fclose(fp);
  }
  if (rc != FMBD_OK && tmp) {
    remove(tmp);
  }
  fmbd_free(tmp);
  return rc;
}
