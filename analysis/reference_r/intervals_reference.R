# Reference values for crowdstudy.stats' intervals, effect sizes, simple effects and trends.
#
#   Rscript analysis/reference_r/intervals_reference.R      (run from the repository root)
#
# Reads the committed inputs of make_inputs.py and writes, for each dataset NAME:
#   ref_NAME_confint.csv  confint(pairs(emmeans(fit, spec, model = "multivariate"), adjust = ...))
#                         for the specs of afex_reference.R (lower.CL, upper.CL; emmeans turns
#                         "holm" into "bonferroni" for intervals).
#   ref_NAME_effsize.csv  per-subject paired differences of ~Method | Density * Viewpoint and
#                         ~Density: d_z with its noncentral-t 95 % interval (uniroot on pt(ncp),
#                         tol 1e-13), effectsize::cohens_d(paired = TRUE) for comparison (its
#                         optimiser stops near 1e-6), g_av = J(n-1) mean / ((sd_A + sd_B) / 2)
#                         and its interval (the d_z interval times J sd(d) / sd_av).
#   ref_NAME_joint.csv    joint_tests(fit, by = ...) on the multivariate model for
#                         by = Density,Viewpoint / Viewpoint / Density (joint_tests rounds its
#                         F.ratio to 3 decimals: F_rounded; F_from_p = qf(p, df1, df2) recovers
#                         it from the unrounded p).
#   ref_NAME_poly.csv     contrast(emmeans(fit, ~ Density [| Method]), "poly") with confint
#                         and the contrast coefficients.
#   ref_intervals_versions.csv  R, afex, emmeans and effectsize versions.
# Numbers are written with 17 significant digits.
suppressPackageStartupMessages({library(afex); library(emmeans); library(effectsize)})
afex_options(emmeans_model = "multivariate")

source(file.path("analysis", "reference_r", "common.R"))
by_value <- function(pr, by) {
  cols <- if (by == "") character(0) else strsplit(by, ",")[[1]]
  if (!length(cols)) return(rep("", nrow(pr)))
  apply(pr[, cols, drop = FALSE], 1, function(r) paste(trimws(r), collapse = ","))
}
ncp_limit <- function(t, df, prob) {
  f <- function(ncp) pt(t, df, ncp) - prob
  w <- 10 + abs(t)
  uniroot(f, c(t - w, t + w), tol = 1e-13, extendInt = "downX", maxiter = 2000)$root
}
J <- function(df) exp(lgamma(df / 2) - 0.5 * log(df / 2) - lgamma((df - 1) / 2))

reference <- function(name) {
  d <- read_input(name)
  fit <- aov_ez("subject", "y", d, within = c("Density", "Viewpoint", "Method"))

  specs <- list(list(spec = ~ Density, factor = "Density", by = ""),
                list(spec = ~ Viewpoint, factor = "Viewpoint", by = ""),
                list(spec = ~ Density | Method, factor = "Density", by = "Method"),
                list(spec = ~ Viewpoint | Density, factor = "Viewpoint", by = "Density"),
                list(spec = ~ Method | Density * Viewpoint, factor = "Method", by = "Density,Viewpoint"))
  rows <- list()
  for (sp in specs) {
    em <- emmeans(fit, sp$spec, model = "multivariate")
    for (adjust in c("tukey", "bonferroni", "holm")) {
      ci <- suppressMessages(as.data.frame(confint(pairs(em), adjust = adjust, level = 0.95)))
      rows[[length(rows) + 1]] <- data.frame(factor = sp$factor, by = sp$by, by_level = by_value(ci, sp$by),
                                             contrast = as.character(ci$contrast), adjust = adjust,
                                             estimate = ci$estimate, SE = ci$SE, df = ci$df,
                                             lower_CL = ci$lower.CL, upper_CL = ci$upper.CL,
                                             stringsAsFactors = FALSE)
    }
  }
  write_ref(do.call(rbind, rows), paste0(name, "_confint"))

  # effect sizes from the per-subject marginal means
  es <- list()
  add_es <- function(factor, by_cols, a, b, sub) {
    key <- c("subject", factor)
    m <- aggregate(sub$y, by = sub[key], FUN = mean)
    names(m)[ncol(m)] <- "y"
    m <- m[order(m$subject), ]
    ya <- m$y[m[[factor]] == a]
    yb <- m$y[m[[factor]] == b]
    dif <- ya - yb
    n <- length(dif)
    t <- mean(dif) / (sd(dif) / sqrt(n))
    lo <- ncp_limit(t, n - 1, 0.975) / sqrt(n)
    hi <- ncp_limit(t, n - 1, 0.025) / sqrt(n)
    cd <- suppressMessages(cohens_d(ya, yb, paired = TRUE, ci = 0.95))
    sd_av <- (sd(ya) + sd(yb)) / 2
    scale <- J(n - 1) * sd(dif) / sd_av
    data.frame(factor = factor, by_level = by_cols, contrast = paste(a, "-", b), n = n,
               dz = mean(dif) / sd(dif), dz_low = lo, dz_high = hi,
               effectsize_d = cd$Cohens_d, effectsize_low = cd$CI_low, effectsize_high = cd$CI_high,
               g_av = J(n - 1) * mean(dif) / sd_av, g_av_low = lo * scale, g_av_high = hi * scale,
               stringsAsFactors = FALSE)
  }
  for (dl in levels(d$Density)) for (vl in levels(d$Viewpoint)) {
    sub <- d[d$Density == dl & d$Viewpoint == vl, ]
    es[[length(es) + 1]] <- add_es("Method", paste(dl, vl, sep = ","), "Baseline", "Ours", sub)
  }
  lv <- levels(d$Density)
  for (i in seq_along(lv)) for (j in seq_along(lv)) if (i < j)
    es[[length(es) + 1]] <- add_es("Density", "", lv[i], lv[j], d)
  write_ref(do.call(rbind, es), paste0(name, "_effsize"))

  jt <- list()
  for (by in list(c("Density", "Viewpoint"), "Viewpoint", "Density")) {
    j <- as.data.frame(joint_tests(fit, by = by))
    jt[[length(jt) + 1]] <- data.frame(term = trimws(as.character(j[["model term"]])), by = paste(by, collapse = ","),
                                       by_level = apply(j[, by, drop = FALSE], 1,
                                                        function(r) paste(trimws(r), collapse = ",")),
                                       df1 = j$df1, df2 = j$df2, F_rounded = j$F.ratio, p = j$p.value,
                                       F_from_p = qf(j$p.value, j$df1, j$df2, lower.tail = FALSE),
                                       stringsAsFactors = FALSE)
  }
  write_ref(do.call(rbind, jt), paste0(name, "_joint"))

  pl <- list()
  for (sp in list(list(spec = ~ Density, by = ""), list(spec = ~ Density | Method, by = "Method"))) {
    con <- contrast(emmeans(fit, sp$spec, model = "multivariate"), "poly")
    s <- as.data.frame(summary(con, infer = c(TRUE, TRUE), level = 0.95))
    cf <- coef(con)
    cols <- grep("^c\\.", names(cf), value = TRUE)
    coefs <- vapply(seq_along(cols), function(i) {
      keep <- if (sp$by == "") rep(TRUE, nrow(cf)) else cf[[sp$by]] == s[[sp$by]][i]
      paste(cf[keep, cols[i]], collapse = " ")
    }, "")
    pl[[length(pl) + 1]] <- data.frame(factor = "Density", by = sp$by, by_level = by_value(s, sp$by),
                                       contrast = as.character(s$contrast), coefficients = unname(coefs),
                                       estimate = s$estimate, SE = s$SE, df = s$df, t = s$t.ratio,
                                       p = s$p.value, lower_CL = s$lower.CL, upper_CL = s$upper.CL,
                                       stringsAsFactors = FALSE)
  }
  write_ref(do.call(rbind, pl), paste0(name, "_poly"))
  cat(name, "done\n")
}

for (name in complete_datasets) reference(name)
write_versions("intervals_versions", c("R", "afex", "emmeans", "effectsize"))
