# Reference values for crowdstudy.stats.robust: the mixed model (lme4 / lmerTest) and the
# ordinal checks of the Method effect (wilcox.test, binom.test).
#
#   Rscript analysis/reference_r/robust_reference.R      (run from the repository root)
#
# Writes:
#   ref_likert_incomplete_5x2x2_mixed.csv  lmer(y ~ Density * Viewpoint * Method +
#       (1 + Method | subject), REML, contr.sum, bobyqa with rhoend 1e-12) on the
#       incomplete dataset (most participants lack some cell): one row per fixed effect
#       (estimate, SE, lmerTest Satterthwaite df and p) and rows "var:..." for the variance
#       components and "loglik" for the REML log-likelihood (in the estimate column).
#   ref_NAME_wilcoxon.csv  per Density x Viewpoint cell and over all cells ("all": each
#       subject's mean difference): the Baseline - Ours differences of the cell means,
#       wilcox.test (V, p; exact = NULL, correct = TRUE), binom.test on the signs, t.test.
#   ref_robust_versions.csv  lme4, lmerTest versions.
# Numbers are written with 17 significant digits.
suppressPackageStartupMessages({library(lme4); library(lmerTest)})
options(contrasts = c("contr.sum", "contr.poly"))

source(file.path("analysis", "reference_r", "common.R"))

d <- read_input("likert_incomplete_5x2x2")
m <- lmer(y ~ Density * Viewpoint * Method + (1 + Method | subject), d, REML = TRUE,
          control = lmerControl(optimizer = "bobyqa", optCtrl = list(rhoend = 1e-12, maxfun = 1e5)))
co <- summary(m, ddf = "Satterthwaite")$coefficients
vc <- as.data.frame(VarCorr(m))
vc <- vc[vc$grp == "subject", ]
fixed <- data.frame(term = rownames(co), estimate = co[, "Estimate"], SE = co[, "Std. Error"],
                    df = co[, "df"], p = co[, "Pr(>|t|)"], stringsAsFactors = FALSE)
extra <- data.frame(term = c("var:participant (Intercept)", "var:participant Method1", "var:covariance",
                             "var:residual", "loglik", "n_obs"),
                    estimate = c(vc$vcov[vc$var1 == "(Intercept)" & is.na(vc$var2)],
                                 vc$vcov[vc$var1 == "Method1" & is.na(vc$var2)],
                                 vc$vcov[!is.na(vc$var2)], sigma(m)^2, as.numeric(logLik(m)), nobs(m)),
                    SE = NA, df = NA, p = NA, stringsAsFactors = FALSE)
write_ref(rbind(fixed, extra), "likert_incomplete_5x2x2_mixed")

wil <- function(name) {
  d <- read_input(name)
  w <- reshape(d, idvar = c("subject", "Density", "Viewpoint"), timevar = "Method", direction = "wide")
  w$diff <- w$y.Baseline - w$y.Ours
  rows <- list()
  test <- function(x, cell, dl, vl) {
    wt <- suppressWarnings(wilcox.test(x, exact = NULL, correct = TRUE))
    nz <- x[x != 0]
    bt <- binom.test(sum(nz > 0), length(nz))
    tt <- t.test(x)
    data.frame(cell = cell, Density = dl, Viewpoint = vl, n_pos = sum(x > 0), n_neg = sum(x < 0),
               V = unname(wt$statistic), p_wilcoxon = wt$p.value, p_sign = bt$p.value, p_t = tt$p.value,
               stringsAsFactors = FALSE)
  }
  for (dl in levels(d$Density)) for (vl in levels(d$Viewpoint)) {
    s <- w[w$Density == dl & w$Viewpoint == vl, ]
    s <- s[order(s$subject), ]
    rows[[length(rows) + 1]] <- test(s$diff, paste(dl, vl), dl, vl)
  }
  allm <- aggregate(diff ~ subject, data = w, FUN = mean)
  rows[[length(rows) + 1]] <- test(allm$diff, "all", "", "")
  write_ref(do.call(rbind, rows), paste0(name, "_wilcoxon"))
}
for (name in c("spherical_5x4x2", "likert_5x2x2")) wil(name)
write_versions("robust_versions", c("lme4", "lmerTest"))
cat("done\n")
