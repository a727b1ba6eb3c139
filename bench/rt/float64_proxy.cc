#include "float64_proxy.h"

namespace palpa::bench {

double Float64Field::Phi(const Vec3d& x) const { return PhiInline(x); }

Float64Sample Float64Field::At(const Vec3d& x) const { return AtInline(x); }

namespace {

using detail::AxisVariation;
using detail::Certified;
using detail::Dot;
using detail::Len;
using detail::Sub;

Vec3d Add(const Vec3d& a, const Vec3d& b, double s = 1) { return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]}; }
double L1(const Vec3d& a) { return std::abs(a[0]) + std::abs(a[1]) + std::abs(a[2]); }

}  // namespace

// The same steps as proxy.cc (free fast path, free motion, contact pieces, leaving, force), in
// double, without the fixed point's overflow guards, rounding slack and HIP clamping.
Float64Result Float64Tick(const Float64Field& field, const Float64Params& prm, Float64State& st, const Vec3d& h) {
  Float64Result r;
  const double delta = prm.delta;
  const double piece = 1.5 * delta;
  bool phi_h_known = false;
  double phi_h = 0;
  int samples = 0;
  if (st.valid && st.seated && st.phi > prm.near) {
    const Vec3d d = Sub(h, st.proxy);
    const double reach = AxisVariation(d, field);
    if (reach < st.phi - prm.near) {
      st.phi -= reach;
      st.proxy = h;
      st.last_hip = h;
      st.grad_valid = false;
      r.proxy = h;
      return r;
    }
    phi_h = field.Phi(h);
    phi_h_known = true;
    samples = 1;
    if (phi_h > 0 && Certified(st.phi, phi_h, d, field, delta)) {
      st.proxy = h;
      st.last_hip = h;
      st.phi = phi_h;
      st.grad_valid = false;
      st.hip_phi_bound = phi_h;
      r.proxy = h;
      r.iterations = 1;
      return r;
    }
  }
  if (!st.valid || !st.seated) {
    const double ph = field.Phi(h);
    st = {h, ph, {}, h, false, ph >= 0, true, 0, ph};
    r.proxy = h;
    r.iterations = 1;
    return r;
  }
  const bool fast = AxisVariation(Sub(h, st.last_hip), field) > prm.settle_samples * piece;
  // φ(X_h) every tick, or an upper bound that shows the HIP inside (proxy.cc); in free motion the
  // sample is one of the budget, at the surface one more.
  if (!phi_h_known && st.phi <= prm.near && st.hip_phi_bound < 0) {
    const double up = st.hip_phi_bound + AxisVariation(Sub(h, st.last_hip), field.band());
    if (up < -1) {
      phi_h = up;
      phi_h_known = true;
    }
  }
  if (!phi_h_known) {
    phi_h = field.Phi(h);
    phi_h_known = true;
    if (st.phi > prm.near) samples = 1;
  }
  const double way = 1.5 * delta;  // the floor of contact pieces and the leaving march
  Vec3d p = st.proxy;
  double phi_p = st.phi;
  Vec3d g = st.grad;
  bool grad_valid = st.grad_valid;
  int halvings = 0, gradient_samples = 0;
  bool leave_blocked = false;
  const int max_samples = prm.max_iterations;
  for (int pass = 0; pass < 2 * max_samples + 2 && samples < max_samples && p != h; ++pass) {
    if (phi_p > prm.near) {  // free motion
      if (!phi_h_known) {
        phi_h = field.Phi(h);
        phi_h_known = true;
        ++samples;
        continue;
      }
      const Vec3d d = Sub(h, p);
      if (phi_h > 0 && Certified(phi_p, phi_h, d, field, delta)) {
        p = h;
        phi_p = phi_h;
        grad_valid = false;
        break;
      }
      const double len = Len(d);
      const double rate = std::min(field.norm(), AxisVariation(d, field) / len);
      const double step = rate == 0 ? len : phi_p / rate;
      if (step >= len) {
        p = h;
        phi_p = phi_h;
        grad_valid = false;
        break;
      }
      p = Add(p, d, step / len);
      phi_p = field.Phi(p);
      grad_valid = false;
      ++samples;
      continue;
    }
    if (!grad_valid) {
      const Float64Sample s = field.At(p);
      phi_p = s.phi;
      g = s.grad;
      grad_valid = true;
      ++samples;
      ++gradient_samples;
      continue;
    }
    const double gg = Dot(g, g);
    if (gg < 1.0 / 16) break;
    // Contact iterations.
    bool lagging = false, done = false, leave = false;
    while (samples < max_samples) {
      const Vec3d d = Sub(h, p);
      const double gg_now = Dot(g, g);
      if (gg_now < 1.0 / 16) {
        done = true;
        break;
      }
      const double c = phi_p + Dot(d, g);
      if (!leave_blocked && phi_h >= 0) {
        leave = true;
        break;
      }
      if (samples >= prm.settle_samples && !lagging && !leave_blocked) break;
      const Vec3d dn = {-prm.beta * phi_p / gg_now * g[0], -prm.beta * phi_p / gg_now * g[1],
                        -prm.beta * phi_p / gg_now * g[2]};
      const double along = Dot(d, g) / gg_now;
      Vec3d dt = {prm.gamma * (d[0] - along * g[0]), prm.gamma * (d[1] - along * g[1]),
                  prm.gamma * (d[2] - along * g[2])};
      if (prm.mu_s > 0) {
        const double t_len = Len(dt), depth = std::max(0.0, -c / std::sqrt(gg_now));
        if (t_len <= prm.mu_s * depth) {
          dt = {};
        } else {
          const double keep = (t_len - prm.mu_d * depth) / t_len;
          dt = {dt[0] * keep, dt[1] * keep, dt[2] * keep};
        }
      }
      if (L1(dn) + L1(dt) <= prm.tolerance) {
        r.converged = true;
        done = true;
        break;
      }
      // Planned with the band's bound, as proxy::ContactRun does.
      const Float64Bound& band = field.band();
      const double dn_variation = AxisVariation(dn, band);
      double dt_variation = AxisVariation(dt, band);
      const double first_room = std::max(0.0, phi_p + piece - dn_variation);
      if (dt_variation > first_room && band.norm_helps()) dt_variation = std::min(dt_variation, band.norm() * Len(dt));
      if (halvings > 0) {
        const double s = std::ldexp(1.0, -halvings);
        dt = {dt[0] * s, dt[1] * s, dt[2] * s};
        dt_variation *= s;
      }
      lagging = dt_variation > first_room && (fast || dt_variation > first_room + 4 * piece);
      const int room = (lagging || leave_blocked ? max_samples : std::min(prm.settle_samples, max_samples)) - samples;
      if (room <= 0) break;
      double reached = 0;
      Vec3d e = p;
      bool moved = false, left = false;
      for (int j = 0; j < room; ++j) {
        const double reach = std::min(dt_variation, j == 0 ? first_room : reached + piece);
        if (j > 0 && reach <= reached) break;
        const double f = dt_variation > 0 ? std::min(1.0, reach / dt_variation) : 1.0;
        const Vec3d q = Add(Add(p, dn), dt, f);
        if (q == e) break;
        const bool last = j == room - 1 || reach >= dt_variation;
        const bool with_gradient = last && gradient_samples < prm.gradient_samples;
        Float64Sample s;
        if (with_gradient) {
          s = field.At(q);
          ++gradient_samples;
        } else {
          s.phi = field.Phi(q);
        }
        ++samples;
        const double need = phi_p + s.phi + 2 * way;
        const double piece_variation = (j == 0 ? dn_variation : 0) + (reach - reached);
        const bool in_band = phi_p <= field.background() && s.phi <= field.background();
        if (!(s.phi >= -delta / 2 && (s.phi <= prm.near || leave_blocked) && need >= 0 &&
              ((in_band && piece_variation <= need) || (in_band ? Certified(phi_p, s.phi, Sub(q, e), band, way)
                                                                : Certified(phi_p, s.phi, Sub(q, e), field, way))))) {
          break;
        }
        e = q;
        reached = reach;
        moved = true;
        phi_p = s.phi;
        if (with_gradient) g = s.grad;
        if (phi_p > prm.near) {
          left = true;
          break;
        }
      }
      if (moved) {
        const bool small = L1(Sub(e, p)) <= prm.tolerance;
        p = e;
        halvings = 0;
        if (left) break;
        if (small) {
          r.converged = true;
          done = true;
          break;
        }
      } else if (++halvings > 16) {
        done = true;
        break;
      }
    }
    if (leave) {  // march straight to the HIP in steps certified by construction; blocked: slide
      bool left = false, jumped = false;
      while (samples < max_samples) {
        const Vec3d d = Sub(h, p);
        const double len = Len(d);
        if (len == 0) break;
        const double rate = std::min(field.norm(), AxisVariation(d, field) / len);
        const double budget = phi_p + 2 * delta;
        const double step = rate == 0 ? len : budget / rate;
        if (step >= len && phi_h >= 0) {
          p = h;
          phi_p = phi_h;
          grad_valid = false;
          jumped = true;
          break;
        }
        const Vec3d q = Add(p, d, std::min(step, len) / len);
        if (q == p) break;
        const double phi_q = field.Phi(q);
        ++samples;
        if (phi_q < -delta || !Certified(phi_p, phi_q, Sub(q, p), field, way)) break;
        p = q;
        phi_p = phi_q;
        grad_valid = false;
        if (phi_q > prm.near) {
          left = true;
          break;
        }
      }
      if (jumped) break;
      if (!left && samples < max_samples) leave_blocked = true;
      continue;
    }
    if (done || phi_p <= prm.near) break;  // budget, convergence or nothing to do; else free motion
  }
  const Vec3d last_hip = st.last_hip, last_proxy = st.proxy;
  const double last_pull = st.pull;
  st.proxy = p;
  st.last_hip = h;
  st.phi = phi_p;
  st.grad = g;
  st.grad_valid = grad_valid;
  st.pull = 0;
  st.hip_phi_bound = phi_h;
  r.proxy = p;
  r.iterations = samples;
  if (p == h) return r;
  // The hold rule, the rise limit and the overpower fade of proxy.cc.
  const bool inside_hip = phi_h < 0;
  if (phi_p > prm.near || !(inside_hip || leave_blocked)) return r;
  const double fade = std::floor(prm.max_force * 65536.0 / 1024) / 65536.0;
  const double cap = inside_hip
                         ? last_pull + fade + prm.k * (Len(Sub(h, last_hip)) + std::min(1.0, Len(Sub(p, last_proxy))))
                         : std::max(0.0, last_pull - fade);
  const double limit = std::min(prm.max_force, cap);
  const Vec3d u = Sub(p, h);
  const double len = Len(u);
  const double scale = prm.k * len > limit ? limit / len : prm.k;
  r.force = {u[0] * scale, u[1] * scale, u[2] * scale};
  r.contact = r.force != Vec3d{};
  st.pull = r.contact ? std::min(limit, prm.k * len) : 0;
  return r;
}

}  // namespace palpa::bench
