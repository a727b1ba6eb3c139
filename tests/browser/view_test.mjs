// The browser half of run_view_test.sh: drives Debian's headless Chromium (playwright-core) on
// `palpa view` and checks the page against independent truths — the PLY `palpa mesh` wrote and
// palpad's CSV, both parsed here, not by the page.
//
// Checks: no console errors and no request beyond palpa's server; the canvas is not blank; the
// mesh's triangle count and bounding box equal the PLY's; moving the time slider puts the proxy
// at the CSV's position at that time (within 1e-6 m); play advances the time; the φ slice loads;
// live: the tick counter advances. Screenshots go to --out for a person to look at.
import { createRequire } from 'node:module';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import process from 'node:process';

const require = createRequire(path.join(process.cwd(), 'package.json'));
const { chromium } = require('playwright-core');
const { PNG } = require('pngjs');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1] ?? '';

let failures = 0;
function check(ok, what) {
  console.log(`${ok ? 'PASS' : 'FAIL'}  ${what}`);
  if (!ok) failures += 1;
}

// palpad's CSV: t, hip, proxy, force, contact per row.
function readCsv(file) {
  const lines = readFileSync(file, 'utf8').split('\n').filter((l) => l && !l.startsWith('#'));
  if (!lines[0].startsWith('t_s,hip_x_m')) throw new Error(`${file}: not palpad's CSV`);
  return lines.slice(1).map((l) => l.split(',').map(Number));
}

// Binary little-endian PLY from `palpa mesh`: vertex count, face count, float32 x y z (+ normals).
function readPly(file) {
  const buf = readFileSync(file);
  const end = buf.indexOf('end_header\n') + 'end_header\n'.length;
  const header = buf.subarray(0, end).toString('latin1');
  if (!header.includes('format binary_little_endian 1.0')) throw new Error(`${file}: not binary little-endian PLY`);
  const nv = Number(/element vertex (\d+)/.exec(header)[1]);
  const nf = Number(/element face (\d+)/.exec(header)[1]);
  const props = header.split('element face')[0].match(/property float \w+/g).length;
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < nv; ++i)
    for (let a = 0; a < 3; ++a) {
      const x = buf.readFloatLE(end + 4 * (i * props + a));
      lo[a] = Math.min(lo[a], x);
      hi[a] = Math.max(hi[a], x);
    }
  return { vertices: nv, triangles: nf, lo, hi };
}

// Share of pixels that differ clearly from the page's background (#1d2025) and are lit.
function litShare(pngBytes) {
  const png = PNG.sync.read(pngBytes);
  let lit = 0;
  for (let i = 0; i < png.width * png.height; ++i) {
    const r = png.data[4 * i], g = png.data[4 * i + 1], b = png.data[4 * i + 2];
    const diff = Math.abs(r - 0x1d) + Math.abs(g - 0x20) + Math.abs(b - 0x25);
    if (diff > 48 && r + g + b > 180) lit += 1;
  }
  return lit / (png.width * png.height);
}

// page.waitForFunction evaluates strings in the page, which the server's CSP forbids: poll instead.
async function waitFor(page, fn, timeoutMs, what) {
  const until = Date.now() + timeoutMs;
  for (;;) {
    if (await page.evaluate(fn)) return;
    if (Date.now() > until) throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}`);
    await page.waitForTimeout(100);
  }
}

async function openPage(browser, url, label) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  const origin = new URL(url).origin;
  const problems = [];
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console error: ${m.text()}`); });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('requestfailed', (r) => problems.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
  page.on('request', (r) => {
    if (!r.url().startsWith(origin) && !r.url().startsWith('data:') && !r.url().startsWith('blob:'))
      problems.push(`request beyond palpa's server: ${r.url()}`);
  });
  await page.goto(url);
  await waitFor(page, () => window.palpaView && (window.palpaView.ready || window.palpaView.errors.length > 0), 60000,
    'the page to draw the mesh');
  const errors = await page.evaluate(() => window.palpaView.errors);
  check(errors.length === 0, `${label}: page reports no errors ${errors.length ? JSON.stringify(errors) : ''}`);
  return { page, problems };
}

const browser = await chromium.launch({
  executablePath: '/usr/bin/chromium',
  // No GPU in CI: WebGL through SwiftShader (software).
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--no-sandbox'],
});
try {
  // ---- replay ----
  if (args.replay) {
  const { page, problems } = await openPage(browser, args.replay, 'replay');
  const ply = readPly(args.ply);
  const mesh = await page.evaluate(() => window.palpaView.mesh);
  check(mesh.triangles === ply.triangles && mesh.vertices === ply.vertices,
    `mesh: page ${mesh.triangles} triangles / ${mesh.vertices} vertices, palpa mesh ${ply.triangles} / ${ply.vertices}`);
  const bboxOk = [0, 1, 2].every((a) => mesh.bboxMin[a] === ply.lo[a] && mesh.bboxMax[a] === ply.hi[a]);
  check(bboxOk, `mesh bounding box: page [${mesh.bboxMin}]..[${mesh.bboxMax}], palpa mesh [${ply.lo}]..[${ply.hi}] (exact, float32)`);

  const rows = readCsv(args.csv);
  const csvAt = (t) => { let k = 0; for (let i = 0; i < rows.length; ++i) if (rows[i][0] <= t) k = i; return rows[k]; };
  const contactRows = rows.map((r, i) => (r[10] === 1 ? i : -1)).filter((i) => i >= 0);
  check(contactRows.length > 0, `the replay has ${contactRows.length} contact rows`);
  const picks = [Math.floor(rows.length * 0.1), contactRows[Math.floor(contactRows.length / 3)],
    contactRows[Math.floor((2 * contactRows.length) / 3)], rows.length - 1];
  const seen = [];
  for (const i of picks) {
    await page.locator('#time').fill(String(i));
    const s = await page.evaluate(() => ({ time: window.palpaView.time, proxy: window.palpaView.proxy, hip: window.palpaView.hip }));
    const row = csvAt(s.time);
    const dp = Math.max(...[0, 1, 2].map((a) => Math.abs(s.proxy[a] - row[4 + a])));
    const dh = Math.max(...[0, 1, 2].map((a) => Math.abs(s.hip[a] - row[1 + a])));
    check(dp <= 1e-6 && dh <= 1e-6 && Math.abs(s.time - rows[i][0]) < 1e-12,
      `slider to row ${i} (t = ${s.time} s): proxy off the CSV by ${dp.toExponential(2)} m, HIP by ${dh.toExponential(2)} m (<= 1e-6)`);
    seen.push(s.proxy);
  }
  const moved = Math.hypot(...[0, 1, 2].map((a) => seen[1][a] - seen[2][a]));
  check(moved > 1e-4, `the proxy moved ${(moved * 1e3).toFixed(2)} mm between the two contact rows`);
  // Mid-stroke for the picture: proxy on the surface, HIP inside, the force arrow.
  await page.locator('#time').fill(String(contactRows[Math.floor(contactRows.length / 2)]));
  await page.waitForTimeout(200);
  await page.screenshot({ path: path.join(args.out, 'view-replay.png') });
  const share = litShare(await page.locator('#scene canvas').screenshot());
  check(share > 0.05, `canvas not blank: ${(100 * share).toFixed(1)}% lit, non-background pixels (> 5%)`);
  check(await page.locator('#plots canvas').count() > 0, 'the |f| and penetration plots are drawn');

  // Play from the start at 1x: time advances.
  await page.locator('#time').fill('0');
  // Software WebGL on a loaded machine may take long per frame: wait for progress, then check it
  // did not run ahead of the wall clock at 1x.
  const started = Date.now();
  await page.locator('#play').click();
  let t = 0;
  try {
    await waitFor(page, () => window.palpaView.time > 0.2, 20000, 'play to advance 0.2 s');
  } catch (e) {
    console.log(String(e));
  }
  t = await page.evaluate(() => window.palpaView.time);
  const wall = (Date.now() - started) / 1000;
  check(t > 0.2 && t <= wall + 0.05, `play advances the time at 1x (${t.toFixed(3)} s after ${wall.toFixed(2)} s wall)`);
  await page.locator('#play').click();

  // The φ cross-section through the middle of the grid.
  await page.locator('#time').fill(String(contactRows[Math.floor(contactRows.length / 2)]));
  const sliceResponse = page.waitForResponse((r) => r.url().includes('/api/slice') && r.status() === 200);
  await page.locator('#slice-on').check();
  await sliceResponse;
  await page.waitForTimeout(300);
  await page.screenshot({ path: path.join(args.out, 'view-slice.png') });
  const errs = await page.evaluate(() => window.palpaView.errors);
  check(errs.length === 0, `slice shown without errors ${errs.length ? JSON.stringify(errs) : ''}`);
  check(problems.length === 0, `replay: no console errors, failed requests or foreign requests ${problems.length ? JSON.stringify(problems) : ''}`);
  await page.close();
  }

  // ---- live ----
  if (args.live) {
    const live = await openPage(browser, args.live, 'live');
    await waitFor(live.page, () => window.palpaView.live && typeof window.palpaView.live.ticks === 'number', 20000,
      'the first live status');
    const t0 = await live.page.evaluate(() => window.palpaView.live.ticks);
    await live.page.waitForTimeout(1000);
    const s1 = await live.page.evaluate(() => ({ ...window.palpaView.live, polls: window.palpaView.livePolls }));
    check(s1.ticks > t0, `live: tick counter advances (${t0} -> ${s1.ticks} in 1 s)`);
    const counters = await live.page.evaluate(() => ['c-ticks', 'c-overruns', 'c-max-tick', 'c-clamps', 'c-estops']
      .map((id) => document.getElementById(id).textContent));
    check(counters.every((c) => c !== '–'), `live: counters shown (${counters.join(', ')})`);
    await live.page.screenshot({ path: path.join(args.out, 'view-live.png') });
    check(live.problems.length === 0, `live: no console errors or failed requests ${live.problems.length ? JSON.stringify(live.problems) : ''}`);
    await live.page.close();
  }
} finally {
  await browser.close();
}
console.log(failures === 0 ? 'browser test: all checks passed' : `browser test: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
