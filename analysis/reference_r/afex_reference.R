# Reference values for crowdstudy.stats from R's afex (aov_ez) + car + emmeans.
#
#   Rscript analysis/reference_r/afex_reference.R      (run from the repository root)
#
# Reads the committed inputs written by make_inputs.py (spherical_5x4x2.csv,
# violated_5x4x2.csv, likert_5x2x2.csv) and writes, for each dataset NAME:
#   ref_NAME_anova.csv    one row per effect: car's univariate table (SS, dfs, F, p),
#                         GG/HF epsilons and corrected p (summary(fit$Anova)), Mauchly's W
#                         and p, and afex's anova tables with correction = "GG" and "none"
#                         (dfs, F, ges, pes, p).
#   ref_NAME_posthoc.csv  emmeans pairs() on the multivariate model, adjust = tukey,
#                         bonferroni, holm (estimate, SE, df, t.ratio, p.value).
#   ref_versions.csv      R, afex, car and emmeans versions.
# Numbers are written with 17 significant digits.
suppressPackageStartupMessages({library(afex); library(emmeans)})

source(file.path("analysis", "reference_r", "common.R"))

reference <- function(name) {
  d <- read_input(name)
  fit <- aov_ez("subject", "y", d, within = c("Density", "Viewpoint", "Method"),
                anova_table = list(correction = "GG", es = c("ges", "pes")))
  s <- summary(fit$Anova, multivariate = FALSE)
  uni <- as.data.frame(unclass(s$univariate.tests))
  uni <- uni[rownames(uni) != "(Intercept)", ]
  terms <- rownames(uni)
  out <- data.frame(Source = terms, SS = uni[["Sum Sq"]], num_df = uni[["num Df"]],
                    SS_error = uni[["Error SS"]], den_df = uni[["den Df"]], F = uni[["F value"]],
                    p_unc = uni[["Pr(>F)"]], stringsAsFactors = FALSE)
  adj <- as.data.frame(unclass(s$pval.adjustments))
  sph <- as.data.frame(unclass(s$sphericity.tests))
  out$eps_GG <- ifelse(terms %in% rownames(adj), adj[terms, "GG eps"], NA)
  out$p_GG <- ifelse(terms %in% rownames(adj), adj[terms, "Pr(>F[GG])"], NA)
  out$eps_HF <- ifelse(terms %in% rownames(adj), adj[terms, "HF eps"], NA)
  out$p_HF <- ifelse(terms %in% rownames(adj), adj[terms, "Pr(>F[HF])"], NA)
  out$W <- ifelse(terms %in% rownames(sph), sph[terms, "Test statistic"], NA)
  out$p_W <- ifelse(terms %in% rownames(sph), sph[terms, "p-value"], NA)
  gg <- as.data.frame(anova(fit, correction = "GG", es = c("ges", "pes")))
  none <- as.data.frame(anova(fit, correction = "none", es = c("ges", "pes")))
  out$afex_GG_num_df <- gg[terms, "num Df"]
  out$afex_GG_den_df <- gg[terms, "den Df"]
  out$afex_GG_F <- gg[terms, "F"]
  out$afex_GG_p <- gg[terms, "Pr(>F)"]
  out$ges <- gg[terms, "ges"]
  out$pes <- gg[terms, "pes"]
  out$afex_none_p <- none[terms, "Pr(>F)"]
  out$afex_none_ges <- none[terms, "ges"]
  write_ref(out, paste0(name, "_anova"))

  specs <- list(list(spec = ~ Density, factor = "Density", by = ""),
                list(spec = ~ Viewpoint, factor = "Viewpoint", by = ""),
                list(spec = ~ Density | Method, factor = "Density", by = "Method"),
                list(spec = ~ Viewpoint | Density, factor = "Viewpoint", by = "Density"),
                list(spec = ~ Method | Density * Viewpoint, factor = "Method", by = "Density,Viewpoint"))
  rows <- list()
  for (sp in specs) {
    em <- emmeans(fit, sp$spec, model = "multivariate")
    for (adjust in c("tukey", "bonferroni", "holm")) {
      pr <- as.data.frame(summary(pairs(em, adjust = adjust), infer = c(FALSE, TRUE)))
      by_cols <- if (sp$by == "") character(0) else strsplit(sp$by, ",")[[1]]
      by_val <- if (length(by_cols)) apply(pr[, by_cols, drop = FALSE], 1, function(r) paste(trimws(r), collapse = ",")) else ""
      rows[[length(rows) + 1]] <- data.frame(factor = sp$factor, by = sp$by, by_level = by_val,
                                             contrast = as.character(pr$contrast), adjust = adjust,
                                             estimate = pr$estimate, SE = pr$SE, df = pr$df,
                                             t_ratio = pr$t.ratio, p_value = pr$p.value,
                                             stringsAsFactors = FALSE)
    }
  }
  write_ref(do.call(rbind, rows), paste0(name, "_posthoc"))
  cat(name, "done\n")
}

for (name in c(complete_datasets, k_method_datasets)) reference(name)
write_versions("versions", c("R", "afex", "car", "emmeans"))
