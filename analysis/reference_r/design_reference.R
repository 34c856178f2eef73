# Reference values for the analyses that follow a study design (crowdstudy.stats): k = 3
# methods (the mixed model, rank tests per contrast, Friedman) and a 2AFC stage (choice
# shares with Clopper-Pearson intervals, the per-pair logistic mixed model, Bradley-Terry).
#
#   Rscript analysis/reference_r/design_reference.R      (run from the repository root)
#
# Writes:
#   ref_likert_incomplete_5x2x3_mixed.csv  lmer(y ~ Density * Viewpoint * Method +
#       (1 + Method | subject), REML, contr.sum, bobyqa with rhoend 1e-12) on the incomplete
#       three-method dataset: fixed effects and SEs, rows "var:..." (variance components),
#       "loglik", "n_obs", and "contrast:Baseline - X" (minus the Method coefficient of the
#       same model with contr.treatment for Method: estimate, SE), "loglik_treatment".
#   ref_likert_5x2x3_wilcoxon.csv  per contrast (Baseline - Ours, Baseline - Stiff), per
#       Density x Viewpoint cell and "all": wilcox.test, binom.test on the signs, t.test,
#       and Holm over the two contrasts of each cell (p.adjust).
#   ref_likert_5x2x3_friedman.csv  friedman.test over the three methods per cell and on
#       each subject's method means ("all").
#   ref_comparisons_2afc_shares.csv  per method, per Density x Viewpoint cell and overall
#       ("all"): chosen / shown, binom.test's Clopper-Pearson 95 % interval and p (vs 0.5);
#       method "left": the share of "left" answers (position bias).
#   ref_comparisons_2afc_glmer.csv  per pair (a, b) in the design's order: glmer(chose_b ~
#       Density + (1 | participant), binomial, Laplace (nAGQ = 1), contr.sum, bobyqa, PIRLS
#       tolerance tolPwrss = 1e-12 (the default 1e-7 leaves the log-likelihood ~6e-4 off)):
#       fixed effects, SEs, "var:participant (Intercept)", "loglik".
#   ref_comparisons_2afc_bt.csv  BTm(cbind(win1, win2), player1, player2, refcat =
#       "Baseline") on every trial (no random effect): abilities and SEs, the reference 0,
#       and "loglik".
#   ref_design_versions.csv  lme4, BradleyTerry2 versions.
# Numbers are written with 17 significant digits.
suppressPackageStartupMessages({library(lme4); library(BradleyTerry2)})
options(contrasts = c("contr.sum", "contr.poly"))

source(file.path("analysis", "reference_r", "common.R"))

ctrl <- lmerControl(optimizer = "bobyqa", optCtrl = list(rhoend = 1e-12, maxfun = 1e5))

# 1. the mixed model with three methods
d <- read_input("likert_incomplete_5x2x3")
m <- lmer(y ~ Density * Viewpoint * Method + (1 + Method | subject), d, REML = TRUE, control = ctrl)
co <- summary(m)$coefficients
vc <- as.data.frame(VarCorr(m))
vc <- vc[vc$grp == "subject", ]
fixed <- data.frame(term = rownames(co), estimate = co[, "Estimate"], SE = co[, "Std. Error"],
                    stringsAsFactors = FALSE)
vname <- ifelse(is.na(vc$var2), paste0("var:participant ", vc$var1), paste0("var:covariance ", vc$var1, ":", vc$var2))
extra <- data.frame(term = c(vname, "var:residual", "loglik", "n_obs"),
                    estimate = c(vc$vcov[!is.na(vc$var1)], sigma(m)^2, as.numeric(logLik(m)), nobs(m)),
                    SE = NA, stringsAsFactors = FALSE)
extra <- extra[extra$term != "var:participant NA", ]
dt <- d
contrasts(dt$Method) <- contr.treatment(levels(dt$Method))
mt <- lmer(y ~ Density * Viewpoint * Method + (1 + Method | subject), dt, REML = TRUE, control = ctrl)
ct <- summary(mt)$coefficients
others <- levels(d$Method)[-1]
con <- data.frame(term = c(paste0("contrast:Baseline - ", others), "loglik_treatment"),
                  estimate = c(-ct[paste0("Method", others), "Estimate"], as.numeric(logLik(mt))),
                  SE = c(ct[paste0("Method", others), "Std. Error"], NA), stringsAsFactors = FALSE)
write_ref(rbind(fixed, extra, con), "likert_incomplete_5x2x3_mixed")

# 2. rank tests per contrast and Friedman
d <- read_input("likert_5x2x3")
w <- reshape(d, idvar = c("subject", "Density", "Viewpoint"), timevar = "Method", direction = "wide")
w <- w[order(w$subject), ]
test <- function(x, contrast, cell, dl, vl) {
  wt <- suppressWarnings(wilcox.test(x, exact = NULL, correct = TRUE))
  nz <- x[x != 0]
  bt <- binom.test(sum(nz > 0), length(nz))
  data.frame(contrast = contrast, cell = cell, Density = dl, Viewpoint = vl, n_pos = sum(x > 0),
             n_neg = sum(x < 0), V = unname(wt$statistic), p_wilcoxon = wt$p.value, p_sign = bt$p.value,
             p_t = t.test(x)$p.value, stringsAsFactors = FALSE)
}
rows <- list()
fr <- list()
cells <- list()
for (dl in levels(d$Density)) for (vl in levels(d$Viewpoint)) cells[[length(cells) + 1]] <- c(dl, vl)
for (other in others) {
  w$diff <- w$y.Baseline - w[[paste0("y.", other)]]
  for (cl in cells) {
    s <- w[w$Density == cl[1] & w$Viewpoint == cl[2], ]
    rows[[length(rows) + 1]] <- test(s$diff, paste("Baseline -", other), paste(cl[1], cl[2]), cl[1], cl[2])
  }
  allm <- aggregate(diff ~ subject, data = w, FUN = mean)
  rows[[length(rows) + 1]] <- test(allm$diff, paste("Baseline -", other), "all", "", "")
}
wil <- do.call(rbind, rows)
wil$p_wilcoxon_holm <- ave(wil$p_wilcoxon, wil$cell, FUN = function(p) p.adjust(p, "holm"))
wil$p_sign_holm <- ave(wil$p_sign, wil$cell, FUN = function(p) p.adjust(p, "holm"))
write_ref(wil, "likert_5x2x3_wilcoxon")
ycols <- paste0("y.", levels(d$Method))
for (cl in cells) {
  s <- w[w$Density == cl[1] & w$Viewpoint == cl[2], ]
  ft <- friedman.test(as.matrix(s[, ycols]))
  fr[[length(fr) + 1]] <- data.frame(cell = paste(cl[1], cl[2]), chi2 = unname(ft$statistic), p = ft$p.value)
}
mm <- aggregate(cbind(y.Baseline, y.Ours, y.Stiff) ~ subject, data = w, FUN = mean)
ft <- friedman.test(as.matrix(mm[, ycols]))
fr[[length(fr) + 1]] <- data.frame(cell = "all", chi2 = unname(ft$statistic), p = ft$p.value)
write_ref(do.call(rbind, fr), "likert_5x2x3_friedman")

# 3. 2AFC: shares, position bias, per-pair glmer, Bradley-Terry
cmp <- read.csv(file.path(here, "comparisons_2afc.csv"), stringsAsFactors = FALSE)
methods <- c("Baseline", "Ours", "Stiff")
share <- function(x, n, method, cell) {
  b <- binom.test(x, n)
  data.frame(method = method, cell = cell, chosen = x, shown = n, share = x / n, lower_CL = b$conf.int[1],
             upper_CL = b$conf.int[2], p = b$p.value, stringsAsFactors = FALSE)
}
rows <- list()
cmp$cell <- paste(cmp$density_level, cmp$viewpoint)
for (mth in methods) {
  shown <- cmp$method_left == mth | cmp$method_right == mth
  for (cl in sort(unique(cmp$cell))) {
    s <- shown & cmp$cell == cl
    rows[[length(rows) + 1]] <- share(sum(cmp$chosen_method[s] == mth), sum(s), mth, cl)
  }
  rows[[length(rows) + 1]] <- share(sum(cmp$chosen_method[shown] == mth), sum(shown), mth, "all")
}
rows[[length(rows) + 1]] <- share(sum(cmp$choice == "left"), nrow(cmp), "left", "all")
write_ref(do.call(rbind, rows), "comparisons_2afc_shares")

gctrl <- glmerControl(optimizer = "bobyqa", optCtrl = list(rhoend = 1e-12, maxfun = 1e5), tolPwrss = 1e-12)
rows <- list()
for (pr in list(c("Baseline", "Ours"), c("Baseline", "Stiff"), c("Ours", "Stiff"))) {
  s <- cmp[(cmp$method_left %in% pr) & (cmp$method_right %in% pr), ]
  s$chose_b <- as.integer(s$chosen_method == pr[2])
  s$Density <- factor(s$density_level)
  s$participant <- factor(s$participant_id)
  g <- glmer(chose_b ~ Density + (1 | participant), s, family = binomial, nAGQ = 1, control = gctrl)
  co <- summary(g)$coefficients
  rows[[length(rows) + 1]] <- data.frame(pair = paste(pr, collapse = " vs "),
                                         term = c(rownames(co), "var:participant (Intercept)", "loglik", "n_obs"),
                                         estimate = c(co[, "Estimate"], as.data.frame(VarCorr(g))$vcov[1],
                                                      as.numeric(logLik(g)), nobs(g)),
                                         SE = c(co[, "Std. Error"], NA, NA, NA), stringsAsFactors = FALSE)
}
write_ref(do.call(rbind, rows), "comparisons_2afc_glmer")

options(contrasts = c("contr.treatment", "contr.poly"))  # BTabilities() follows the global option
bt <- data.frame(player1 = factor(cmp$method_left, levels = methods),
                 player2 = factor(cmp$method_right, levels = methods))
bt$win1 <- as.integer(cmp$choice == "left")
bt$win2 <- 1L - bt$win1
fit <- BTm(cbind(win1, win2), player1, player2, data = bt, refcat = "Baseline")
ab <- BTabilities(fit)
write_ref(data.frame(term = c(rownames(ab), "loglik"), estimate = c(ab[, "ability"], as.numeric(logLik(fit))),
                     SE = c(ab[, "s.e."], NA), stringsAsFactors = FALSE), "comparisons_2afc_bt")
write_versions("design_versions", c("R", "lme4", "BradleyTerry2"))
cat("done\n")
